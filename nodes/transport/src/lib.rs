//! Transport and bag I/O.
pub mod bag;

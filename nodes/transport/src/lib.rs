//! Transport and bag I/O.

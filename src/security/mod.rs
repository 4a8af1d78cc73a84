//! SROS2 for the cell: the keystore (`keystore`: CA, governance, enclaves as sros2 lays them
//! out) and the default policy of each rpkm program (`policy`: the DDS topics it may write
//! and read). The nodes read the keystore through `rpkm_transport::security`.

pub mod keystore;
pub mod policy;

pub use keystore::{Created, Keystore, KeystoreError};
pub use policy::{Grant, PolicyError};

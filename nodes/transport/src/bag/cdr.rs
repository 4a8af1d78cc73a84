//! CDR payloads as ROS 2 stores them: the one codec of the workspace, `rpkm_msgs::cdr`, with
//! the bag's names.

use serde::{de::DeserializeOwned, Serialize};

pub use rpkm_msgs::cdr::CdrError;

/// Serialises `message` into `out` (cleared first): `00 01 00 00` then little-endian CDR.
pub fn encode_cdr<T: Serialize>(message: &T, out: &mut Vec<u8>) -> Result<(), CdrError> {
    rpkm_msgs::cdr::to_cdr_into(message, out)
}

/// Deserialises a payload with its encapsulation header (`CDR_LE` or `CDR_BE`).
///
/// Bytes after the value (alignment padding) are ignored, as ROS 2 readers do.
pub fn decode_cdr<T: DeserializeOwned>(payload: &[u8]) -> Result<T, CdrError> {
    rpkm_msgs::cdr::from_cdr(payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Sample {
        a: u8,
        b: f64,
        c: String,
        d: Vec<i32>,
    }

    #[test]
    fn round_trip_keeps_header_and_values() {
        let value = Sample {
            a: 7,
            b: -1.25e-3,
            c: "x".into(),
            d: vec![1, -2, 3],
        };
        let mut buf = Vec::new();
        encode_cdr(&value, &mut buf).expect("encodes");
        assert_eq!(&buf[..4], &rpkm_msgs::cdr::CDR_LE_HEADER);
        // u8 at 0, f64 aligned to 8 (relative to the body), string length at 16.
        assert_eq!(&buf[4 + 8..4 + 16], &(-1.25e-3f64).to_le_bytes());
        let back: Sample = decode_cdr(&buf).expect("decodes");
        assert_eq!(back, value);
    }

    #[test]
    fn short_and_foreign_payloads_are_errors() {
        assert!(matches!(
            decode_cdr::<Sample>(&[0, 1]),
            Err(CdrError::Truncated { len: 2 })
        ));
        assert!(matches!(
            decode_cdr::<Sample>(&[0, 0x11, 0, 0, 1]),
            Err(CdrError::Encapsulation { found: [0, 0x11] })
        ));
        assert!(matches!(
            decode_cdr::<Sample>(&[0, 1, 0, 0, 1]),
            Err(CdrError::Body { .. })
        ));
    }
}

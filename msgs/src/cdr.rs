//! CDR (XCDR1, little endian) encoding of whole messages, as on the ROS 2 wire and in
//! MCAP `cdr` channels: a 4-byte encapsulation header, then the serialised body.

use serde::{de::DeserializeOwned, Serialize};

/// Encapsulation header of little-endian plain CDR (`CDR_LE`).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Encapsulation header of big-endian plain CDR (`CDR_BE`).
const CDR_BE_HEADER: [u8; 2] = [0x00, 0x00];

/// Failure to encode or decode a CDR message.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// The buffer is shorter than the 4-byte encapsulation header.
    #[error("CDR buffer of {len} bytes has no 4-byte encapsulation header")]
    Truncated {
        /// Length of the buffer.
        len: usize,
    },
    /// The encapsulation is not plain CDR (XCDR2 and parameter lists are not supported).
    #[error(
        "unsupported CDR encapsulation {found:02x?}; expected 00 01 (CDR_LE) or 00 00 (CDR_BE)"
    )]
    Encapsulation {
        /// The first two bytes found.
        found: [u8; 2],
    },
    /// The body does not decode as the expected type.
    #[error("CDR body does not decode as {type_name}: {reason}")]
    Body {
        /// Rust type expected.
        type_name: &'static str,
        /// The decoder's message.
        reason: String,
    },
    /// Serialisation failed (e.g. a sequence longer than 2^32 - 1).
    #[error("cannot encode {type_name} as CDR: {reason}")]
    Encode {
        /// Rust type encoded.
        type_name: &'static str,
        /// The encoder's message.
        reason: String,
    },
}

/// Encodes `msg` into `out` (cleared first, its capacity kept: the bag writer's one buffer):
/// header `00 01 00 00`, then the little-endian CDR body.
pub fn to_cdr_into<T: Serialize>(msg: &T, out: &mut Vec<u8>) -> Result<(), CdrError> {
    out.clear();
    out.extend_from_slice(&CDR_LE_HEADER);
    cdr_encoding::to_writer::<T, byteorder::LittleEndian, _>(&mut *out, msg).map_err(|e| {
        CdrError::Encode {
            type_name: std::any::type_name::<T>(),
            reason: e.to_string(),
        }
    })
}

/// Encodes `msg` as header `00 01 00 00` followed by its little-endian CDR body.
pub fn to_cdr<T: Serialize>(msg: &T) -> Result<Vec<u8>, CdrError> {
    let body =
        cdr_encoding::to_vec::<T, byteorder::LittleEndian>(msg).map_err(|e| CdrError::Encode {
            type_name: std::any::type_name::<T>(),
            reason: e.to_string(),
        })?;
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    Ok(out)
}

/// Decodes a message with its encapsulation header (little or big endian plain CDR).
pub fn from_cdr<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    let (Some(header), Some(body)) = (bytes.get(..4), bytes.get(4..)) else {
        return Err(CdrError::Truncated { len: bytes.len() });
    };
    let body_err = |e: cdr_encoding::Error| CdrError::Body {
        type_name: std::any::type_name::<T>(),
        reason: e.to_string(),
    };
    if header[..2] == CDR_LE_HEADER[..2] {
        cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body)
            .map(|(v, _)| v)
            .map_err(body_err)
    } else if header[..2] == CDR_BE_HEADER {
        cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body)
            .map(|(v, _)| v)
            .map_err(body_err)
    } else {
        Err(CdrError::Encapsulation {
            found: [header[0], header[1]],
        })
    }
}

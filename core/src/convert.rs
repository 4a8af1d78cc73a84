//! Float to integer conversions, with their rounding and saturation stated once.
//!
//! Rust's `as` from a float saturates at the integer type's bounds and maps NaN to 0; these
//! functions name which rounding the caller wants, so that a pixel, a sample count or a
//! timestamp says what happens at the edges instead of leaving it to a cast.
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "the one place where floats become integers: saturating `as`, NaN and negatives to 0"
)]

/// `x` rounded to the nearest count; NaN and negatives give 0, too large saturates.
pub fn round_count(x: f64) -> usize {
    x.round().max(0.0) as usize
}

/// `x` rounded up to a count; NaN and negatives give 0, too large saturates.
pub fn ceil_count(x: f64) -> usize {
    x.ceil().max(0.0) as usize
}

/// `x` rounded down to a count; NaN and negatives give 0, too large saturates.
pub fn floor_count(x: f64) -> usize {
    x.floor().max(0.0) as usize
}

/// `x` rounded to the nearest `u64`; NaN and negatives give 0, too large saturates.
pub fn round_u64(x: f64) -> u64 {
    x.round().max(0.0) as u64
}

/// `x` rounded to the nearest `u32`; NaN and negatives give 0, too large saturates.
pub fn round_u32(x: f64) -> u32 {
    x.round().max(0.0) as u32
}

/// `x` rounded to the nearest `u8`; NaN and negatives give 0, above 255 gives 255.
pub fn round_u8(x: f64) -> u8 {
    x.round().max(0.0) as u8
}

/// `x` rounded to the nearest `i64`; NaN gives 0, out of range saturates.
pub fn round_i64(x: f64) -> i64 {
    x.round() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_are_what_the_names_say() {
        assert_eq!(round_count(2.5), 3);
        assert_eq!(round_count(-3.0), 0);
        assert_eq!(round_count(f64::NAN), 0);
        assert_eq!(ceil_count(2.01), 3);
        assert_eq!(floor_count(2.99), 2);
        assert_eq!(round_u8(300.0), 255);
        assert_eq!(round_u32(f64::INFINITY), u32::MAX);
        assert_eq!(round_u64(1e3), 1000);
        assert_eq!(round_i64(-2.6), -3);
        assert_eq!(round_i64(f64::NAN), 0);
    }
}

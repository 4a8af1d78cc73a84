//! `builtin_interfaces/msg/Time`.

#[cfg(feature = "zero-copy")]
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`: a point in time (ROS time, usually since the Unix epoch).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
#[cfg_attr(feature = "zero-copy", derive(ZeroCopySend))]
#[cfg_attr(
    feature = "zero-copy",
    type_name("builtin_interfaces::msg::dds_::Time_")
)]
#[repr(C)]
pub struct Time {
    /// `int32 sec`: seconds (s).
    pub sec: i32,
    /// `uint32 nanosec`: nanoseconds within the second, 0..1e9 (ns).
    pub nanosec: u32,
}

const _: () = assert!(core::mem::size_of::<Time>() == 8);

/// The `.msg` text of `builtin_interfaces/msg/Time`.
pub const TIME_MSG: &str = "\
# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

# The seconds component, valid over all int32 values.
int32 sec

# The nanoseconds component, valid in the range [0, 1e9), to be added to the seconds component.
# e.g.
# The time -1.7 seconds is represented as {sec: -2, nanosec: 3e8}
# The time 1.7 seconds is represented as {sec: 1, nanosec: 7e8}
uint32 nanosec
";

crate::ros_message!(Time, "builtin_interfaces", "Time", TIME_MSG, []);

impl Time {
    /// From nanoseconds since the epoch; saturates outside the `i32` seconds range.
    pub fn from_nanos(ns: i128) -> Self {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = u32::try_from(ns.rem_euclid(1_000_000_000)).unwrap_or(0);
        match i32::try_from(sec) {
            Ok(sec) => Self { sec, nanosec },
            Err(_) if sec < 0 => Self {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => Self {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }

    /// Nanoseconds since the epoch.
    pub fn as_nanos(&self) -> i128 {
        i128::from(self.sec) * 1_000_000_000 + i128::from(self.nanosec)
    }

    /// The current system time.
    pub fn now() -> Self {
        let ns = match std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
            Ok(d) => d.as_nanos().cast_signed(),
            Err(e) => -e.duration().as_nanos().cast_signed(),
        };
        Self::from_nanos(ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nanos_round_trip() {
        for ns in [0i128, 1, -1, 1_700_000_000_123_456_789, -1_700_000_000] {
            assert_eq!(Time::from_nanos(ns).as_nanos(), ns);
        }
        assert_eq!(
            Time::from_nanos(-1_700_000_000),
            Time {
                sec: -2,
                nanosec: 300_000_000
            }
        );
    }
}

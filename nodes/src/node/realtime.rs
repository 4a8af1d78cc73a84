//! Real-time scheduling of a servo-rate node (parameter `rt_priority`).
//!
//! With SCHED_FIFO the node runs as soon as its wake-up arrives, ahead of every normal
//! process, so a busy host no longer delays the estimate by a scheduler time slice
//! (milliseconds). Such a node must block between samples (`busy_poll_ms: 0`): a spinning
//! FIFO task would take its core until the kernel's real-time throttling stops it.

use super::declare::{ParamBound, ParamDefault, ParamSpec};
use super::params::{BUSY_POLL_MS, RT_PRIORITY};

/// Parameter `busy_poll_ms` of a servo-rate node.
pub const BUSY_POLL: ParamSpec = ParamSpec::fixed(
    "busy_poll_ms",
    ParamDefault::F64(0.0),
    "yield-polling time after a sample before sleeping",
)
.unit("ms")
.bound(ParamBound::Within(BUSY_POLL_MS.0, BUSY_POLL_MS.1));
/// Parameter `rt_priority` of a servo-rate node.
pub const PRIORITY: ParamSpec = ParamSpec::fixed(
    "rt_priority",
    ParamDefault::U64(0),
    "SCHED_FIFO priority of the estimating thread, 0 for none",
)
.bound(ParamBound::Count(RT_PRIORITY.0, RT_PRIORITY.1));

/// Why real-time scheduling could not be set.
#[derive(Debug, thiserror::Error)]
pub enum RealtimeError {
    #[error("rt_priority {0}: expected 0 (off) or 1..=99 (SCHED_FIFO priority)")]
    Priority(u64),
    #[error(
        "rt_priority {priority}: sched_setscheduler(SCHED_FIFO) failed: {source} \
         (needs root or CAP_SYS_NICE, or an rtprio limit in /etc/security/limits.conf)"
    )]
    Scheduler {
        priority: u64,
        #[source]
        source: std::io::Error,
    },
}

/// Switches this process to SCHED_FIFO at `priority` and locks its memory (no page fault in
/// the loop); 0 leaves the normal scheduler. A failed memory lock only costs determinism and
/// is reported in the returned note.
pub fn set_fifo(priority: u64) -> Result<Option<String>, RealtimeError> {
    if priority == 0 {
        return Ok(None);
    }
    let prio = libc::c_int::try_from(priority)
        .ok()
        .filter(|p| (1..=99).contains(p))
        .ok_or(RealtimeError::Priority(priority))?;
    let param = libc::sched_param {
        sched_priority: prio,
    };
    // SAFETY: sched_setscheduler on pid 0 (this process) with a valid, initialised param.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &raw const param) };
    if rc != 0 {
        return Err(RealtimeError::Scheduler {
            priority,
            source: std::io::Error::last_os_error(),
        });
    }
    // SAFETY: mlockall only changes this process's paging; flags are valid constants.
    let locked = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0;
    Ok(Some(if locked {
        format!("SCHED_FIFO priority {prio}, memory locked")
    } else {
        format!(
            "SCHED_FIFO priority {prio}; memory not locked: {}",
            std::io::Error::last_os_error()
        )
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_is_off_and_out_of_range_is_refused() {
        assert!(matches!(set_fifo(0), Ok(None)));
        let e = set_fifo(100).expect_err("100 is not a FIFO priority");
        assert!(matches!(e, RealtimeError::Priority(100)), "{e}");
        assert!(e.to_string().contains("1..=99"), "{e}");
    }
}

//! `rpkm-node`: the node set as a program of its own, the one `rpkm launch` starts. It links
//! this crate and what it is made of (the core, the transport, the messages, the history),
//! none of the command line's charts, terminal monitor or keystore writer; `rpkm node` runs
//! the same [`crate::node::run`] inside the whole command line.
//!
//! ```text
//! rpkm-node tcp_estimator --params launch_scripts/params.yaml --backend both
//! rpkm-node ingest --source joint_states --params cell.yaml --ros-args -r __ns:=/machine_a
//! ```

use clap::Parser;

/// The name of the node program, as it lies beside `rpkm` once built or installed.
pub const NODE_PROGRAM: &str = "rpkm-node";

/// One ROS 2 node of rpkm: ingest, tcp_estimator, calibrator or preload_monitor (the same
/// node as `rpkm node NAME ...`, in a process that links only the node set).
#[derive(Parser, Debug)]
#[command(name = "rpkm-node", version)]
struct NodeProgram {
    #[command(flatten)]
    node: crate::node::NodeArgs,
}

/// Keeps freed memory in the process for the next allocation. A calibration or diagnosis of
/// 10⁵ poses allocates and frees row buffers of tens of MB per fit, dozens of fits per
/// diagnosis; by default glibc gives such blocks back to the kernel (mmap/munmap, and a
/// trimmed heap) and the next fit faults every page in again. Kept, the 10⁵-pose diagnosis
/// faulted 0.75 M pages instead of 1.17 M and took 8.3 s instead of 8.9 (medians, alternated;
/// docs/diagnosis.md, "At scale"); the process holds its peak, 1.55 GB there against 1.06.
/// Called first by both programs, so that a node (the calibrator fits) runs as it did
/// inside `rpkm`.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn keep_freed_memory() {
    // blocks up to 1 GB from the heap, not mmap (the row buffers are tens of MB: at 32 MB
    // the diagnosis took 8.5-8.6 s, at 1 GB 7.8-8.0 s, one day's runs), and no trimming
    const MMAP_THRESHOLD: libc::c_int = 1 << 30;
    // SAFETY: mallopt(3) with valid parameters, called from main before any thread is
    // started; a value glibc refuses leaves its default (return value 0), nothing else.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD);
        libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn keep_freed_memory() {}

/// The `main` of `rpkm-node`: the node its arguments name, until SIGINT/SIGTERM (or the end
/// of ingest's input); an error is printed with its causes and exits with its code (2: bad
/// input or configuration), as `rpkm node` does.
pub fn main() {
    keep_freed_memory();
    let args = NodeProgram::parse();
    crate::logging::init();
    if let Err(e) = crate::node::run(&args.node) {
        eprintln!("error: {}", crate::error::error_chain(&e));
        std::process::exit(crate::error::exit_code(&e));
    }
}

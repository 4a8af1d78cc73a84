//! Fuzzed input through the real command line, judged against the contract, not the code:
//! whatever a user hands rpkm, it ends with 0 or 2, never a panic (101), an abort or another
//! signal, never a hang; and a rejection (2) names its place: the file it read. Eight
//! families, fixed seeds, 3,950 cases (sized to CI's 15 minutes; raise the counts for a
//! longer run):
//! - campaign CSV through `rpkm calibrate` (a small tracker campaign, mutated);
//! - rosbag2 bags through `rpkm bag info` (the reference calibration bag, bytes flipped,
//!   cut, metadata.yaml edited);
//! - node parameter YAML through `rpkm node ingest --params` (the shipped file, mutated; the
//!   source is a missing file, so a node whose parameters pass exits 2 naming that file);
//! - launch YAML through `rpkm launch --check` (the shipped launch file, mutated: values, key
//!   typos, indentation, lines, bytes); a rejection names the launch file and a line;
//! - issue 29's: launches that run (a node's name, arguments, parameters mutated: never
//!   restarted in a loop), parameter maps where values belong (refused with their key),
//!   bags with corrupt payloads through `rpkm replay` and `rpkm bag campaign` (replay's 2
//!   names bag, topic and message), validation campaigns (a reading 5 m off refused with
//!   its line).
//!
//! A failing case is left in `target/fuzz-failures/` with the command that failed.
//!
//! Files, one job each:
//! - `harness.rs`: What every family shares: mutating text, running rpkm with a time limit,
//!   judging its end, keeping a failing case.
//! - `files.rs`: Campaign CSV, rosbag2 bags and node parameter files, mutated.
//! - `launch.rs`: Launch files, mutated: checked (`--check`) and run (never restarted in a
//!   loop).
//! - `payloads.rs`: Parameter maps where values belong, bags with corrupt payloads,
//!   validation campaigns with a reading moved.

mod files;
mod harness;
mod launch;
mod payloads;

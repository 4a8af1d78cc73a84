//! Units between the core and the topics: the core works in mm, rad, N, s (the thesis's),
//! the ROS topics in SI (REP 103). The one factor between them lives here; campaigns
//! (`campaign_bag`), streams and the nodes convert with it.

/// Millimetres per metre.
pub const MM_PER_M: f64 = 1000.0;

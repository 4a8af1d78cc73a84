//! The machine's history as the command line and the nodes keep and show it: a calibration
//! made into a record ([`record_of`]: its campaign's digest, the tolerance it was judged
//! against), and a machine's records analysed ([`analyse`]: what changed between two, each
//! parameter's trend and when it leaves its tolerance). The arithmetic is the core's
//! (`rpkm_core::history`), the store `rpkm_history`'s; the words are [`words`], the table
//! [`csv`], the page `crate::report::history`.

mod analysis;
pub mod csv;
mod json;
mod record;
pub mod words;

pub use analysis::{analyse, charted, Analysis, ParamTrend, TREND_SIGMA};
pub use json::to_json;
pub use record::{campaign_digest, record_of, time_of, Made};

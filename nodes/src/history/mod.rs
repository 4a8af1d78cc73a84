//! The machine's history as the command line and the nodes keep and show it: a calibration
//! made into a record ([`record_of`]: its campaign's digest, the tolerance it was judged
//! against), and a machine's records analysed ([`analyse`]: what changed between two, each
//! parameter's trend and when it leaves its tolerance). The arithmetic is the core's
//! (`rpkm_core::history`), the store `rpkm_history`'s; the words are [`words`] (the
//! calibrator's log says what changed since the last calibration). What only `rpkm history`
//! writes, its table and JSON, is the command line's, as is the page (its `report::history`).

mod analysis;
mod record;
pub mod words;

pub use analysis::{analyse, charted, Analysis, ParamTrend, TREND_SIGMA};
pub use record::{campaign_digest, record_of, time_of, Made};

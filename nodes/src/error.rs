//! Errors and exit codes of every command and node: bad input (a file, an argument, a
//! parameter, data the model cannot use) exits 2, anything else 1. The command line and the
//! nodes both use this module; it names neither.

/// Bad input from the user (a file, an argument, a parameter): the process exits with code 2,
/// and `rpkm launch` does not restart a node that exits so.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// An error that makes the process exit with code 2.
pub fn bad_input(msg: String) -> anyhow::Error {
    anyhow::Error::new(BadInput(msg))
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message
/// before it already contains (errors that print their source inline).
pub fn error_chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let line = cause.to_string();
        if !text.contains(&line) {
            if !text.is_empty() {
                text.push_str(": ");
            }
            text.push_str(&line);
        }
    }
    text
}

/// Whether an error in a chain is the input's fault: a [`BadInput`], a campaign file the
/// reader refuses, a bag that cannot be opened or decoded (missing, not a bag, corrupt, a
/// payload that is not its topic's type), history settings the database refuses (a bad URL,
/// a password missing or wrong), or data the model cannot use (a pose it cannot evaluate, a calibration that
/// the campaign cannot determine or that diverges on it, a diagnosis that fails on it). The
/// core's solvers converge on every campaign of the spec's machine, so their failure says the
/// data are not such a campaign.
fn is_bad_input(c: &(dyn std::error::Error + 'static)) -> bool {
    c.is::<BadInput>()
        || c.is::<rpkm_core::campaign::CampaignError>()
        || c.is::<rpkm_core::obs::PoseError>()
        || c.is::<rpkm_core::calib::CalibrationError>()
        || c.is::<rpkm_core::diagnose::DiagnoseError>()
        || c.is::<rpkm_core::plan::PlanError>()
        || c.is::<rpkm_core::plan::csv::PlanCsvError>()
        || c.is::<rpkm_transport::bag::BagOpenError>()
        || c.is::<rpkm_transport::bag::BagDecodeError>()
        || c.is::<rpkm_transport::security::SecurityError>()
        || c.downcast_ref::<rpkm_history::StoreError>()
            .is_some_and(|e| e.fault() == rpkm_history::StoreFault::Configuration)
}

/// Exit code of an error: 2 for bad input anywhere in the chain (see [`is_bad_input`]),
/// 1 otherwise.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    if e.chain().any(is_bad_input) {
        2
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_exits_2_through_context_other_errors_1() {
        let e = bad_input("c.csv:3:5 (q1): expected a number".into()).context("calibrating");
        assert_eq!(exit_code(&e), 2);
        assert_eq!(
            error_chain(&e),
            "calibrating: c.csv:3:5 (q1): expected a number"
        );
        assert_eq!(exit_code(&anyhow::anyhow!("disk full")), 1);
        let diverged = rpkm_core::calib::CalibrationError::NotConverged {
            iterations: 400,
            cost: 2.4e10,
            gradient: 9.5e3,
        };
        assert_eq!(
            exit_code(&anyhow::Error::new(diverged).context("calibrating c.csv")),
            2
        );
    }
}

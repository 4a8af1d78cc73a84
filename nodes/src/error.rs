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

/// Exit code of an error: 2 for bad input (a [`BadInput`] or a campaign file's
/// [`CampaignError`](rpkm_core::campaign::CampaignError) anywhere in the chain), 1 otherwise.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    if e.chain()
        .any(|c| c.is::<BadInput>() || c.is::<rpkm_core::campaign::CampaignError>())
    {
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
    }
}

//! What every family shares: mutating text, running rpkm with a time limit, judging its end,
//! keeping a failing case.

use crate::fuzz_support::Rng;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Values a field may be mutated to: the ones a careless export, a unit mix-up or a broken
/// tool produces.
pub(super) const ODD_VALUES: [&str; 18] = [
    "nan",
    "inf",
    "-inf",
    "1e309",
    "-1e300",
    "1e15",
    "0x10",
    "",
    " ",
    "true",
    "1,5",
    "-0",
    "1e-320",
    "12abc",
    "\u{feff}3",
    "999999999999999999999",
    "١٢",
    "\"7\"",
];

/// One mutation of a text file: a field, a line, the bytes.
pub(super) fn mutate_text(text: &str, rng: &mut Rng) -> Vec<u8> {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let n = lines.len();
    match rng.below(8) {
        0..=2 => {
            let i = rng.below(n);
            let mut fields: Vec<String> = lines[i].split(',').map(str::to_owned).collect();
            let k = rng.below(fields.len());
            rng.pick(&ODD_VALUES).clone_into(&mut fields[k]);
            lines[i] = fields.join(",");
        }
        3 => {
            let i = rng.below(n);
            lines.remove(i);
        }
        4 => {
            let (i, j) = (rng.below(n), rng.below(n));
            lines.swap(i, j);
        }
        5 => {
            let i = rng.below(n);
            let extra = format!("{},{}", lines[i], rng.pick(&ODD_VALUES));
            lines[i] = extra;
        }
        _ => {}
    }
    let mut bytes = lines.join("\n").into_bytes();
    match rng.below(6) {
        0 => {
            let at = rng.below(bytes.len());
            bytes[at] = (rng.next() & 0xff) as u8;
        }
        1 => bytes.truncate(rng.below(bytes.len())),
        2 => {
            let at = rng.below(bytes.len());
            bytes.splice(at..at, [0xff, 0xfe, 0xc3]);
        }
        _ => {}
    }
    bytes
}

/// Whether `stderr` names `file` with a line: `file:N` with N >= 1.
pub(super) fn names_a_line(stderr: &str, file: &str) -> bool {
    stderr.match_indices(&format!("{file}:")).any(|(at, m)| {
        let digits: String = stderr[at + m.len()..]
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        digits.parse::<u64>().is_ok_and(|n| n >= 1)
    })
}

/// What one run did.
pub(super) struct Outcome {
    pub(super) code: Option<i32>,
    pub(super) hung: bool,
    pub(super) stderr: String,
}

/// Runs `cmd` with a time limit, killing it when it hangs.
pub(super) fn run(mut cmd: Command, limit: Duration) -> Outcome {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn rpkm");
    let mut stderr_pipe = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut stderr_pipe, &mut s);
        s
    });
    let start = Instant::now();
    let (code, hung) = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break (status.code(), false);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break (None, true);
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Outcome {
        code,
        hung,
        stderr: reader.join().unwrap_or_default(),
    }
}

/// A case that broke the contract, or None: exit 0 or 2 in time, and a 2 names one of
/// `places`.
pub(super) fn judge(out: &Outcome, places: &[String]) -> Option<String> {
    if out.hung {
        return Some("hung".to_owned());
    }
    match out.code {
        Some(0) => None,
        Some(2) if places.iter().any(|p| out.stderr.contains(p.as_str())) => None,
        Some(2) => Some(format!("exit 2 without naming {places:?}")),
        Some(c) => Some(format!("exit {c}")),
        None => Some("killed by a signal".to_owned()),
    }
}

pub(super) fn rpkm() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rpkm"));
    cmd.env("RUST_BACKTRACE", "0");
    cmd
}

/// A tracker campaign of the twin (seed `seed`) written to `file`: a family's valid start.
pub(super) fn simulated_lt_campaign(file: &Path, seed: &str) {
    let made = rpkm()
        .args(["simulate", "--campaign", "lt", "--seed", seed, "--out"])
        .arg(file)
        .output()
        .expect("rpkm simulate");
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
}

pub(super) fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rpkm-fuzz-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// Keeps a failing case for a human: its input and what went wrong.
pub(super) fn keep(family: &str, case: usize, input: &Path, why: &str, out: &Outcome) -> String {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-failures");
    let _ = std::fs::create_dir_all(&dir);
    let to = dir.join(format!("{family}-{case}"));
    let _ = copy_any(input, &to);
    format!(
        "{family} case {case} ({}): {why}\n{}",
        to.display(),
        out.stderr.lines().take(6).collect::<Vec<_>>().join("\n")
    )
}

pub(super) fn copy_any(from: &Path, to: &Path) -> std::io::Result<()> {
    if from.is_dir() {
        std::fs::create_dir_all(to)?;
        for entry in std::fs::read_dir(from)? {
            let entry = entry?;
            std::fs::copy(entry.path(), to.join(entry.file_name()))?;
        }
        Ok(())
    } else {
        std::fs::copy(from, to).map(|_| ())
    }
}

/// Runs `cases` cases of one family on two threads (each returns its broken contract, if
/// any, and whether the input was rejected); returns the broken ones, after checking that
/// the mutations bite (a fuzzer whose inputs all pass tests nothing).
pub(super) fn family(
    cases: usize,
    one: impl Fn(usize) -> (Option<String>, bool) + Sync,
) -> Vec<String> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let rejected = std::sync::atomic::AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let case = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if case >= cases {
                    break;
                }
                let (failure, was_rejected) = one(case);
                if was_rejected {
                    rejected.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                if let Some(f) = failure {
                    failures
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push(f);
                }
            });
        }
    });
    let rejected = rejected.into_inner();
    assert!(
        rejected * 5 >= cases,
        "only {rejected} of {cases} mutated inputs were rejected"
    );
    failures
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

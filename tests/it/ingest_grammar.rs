//! One campaign grammar: `rpkm node ingest` (stdin and file sources) rejects exactly the rows
//! that `rpkm calibrate` rejects, with the same message. A few hundred mutated campaign files
//! (fixed seed): fields set to nan, inf, 1e300, garbage, `true`, nothing, extra columns,
//! unreachable actuator positions, invalid UTF-8, time going back, a setup renamed. Each file is
//! judged by the core's reader (read on after each error, as a stream is) and fed to the node;
//! the node's logged rejects must be that list, the first of them `Campaign::parse_bytes`'s
//! error, and for every tenth rejected file `rpkm calibrate`'s message and exit code 2.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

use rpkm_core::campaign::{Campaign, CampaignReader};

const FILES: usize = 240;

use crate::fuzz_support;
use fuzz_support::Rng;

/// The base: the first setup of each instrument the twin measures with (tracker, grid
/// encoder, ball-bar, self-calibration), 8 rows each, from `rpkm simulate` (the repository's
/// own campaign source: the test needs no data beside the clone). It must read cleanly, so
/// that every reject below is a mutation's.
fn base(dir: &Path) -> Vec<Vec<u8>> {
    let path = dir.join("base.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args([
            "simulate",
            "--campaign",
            "lt,kgm,dbb,self",
            "--validation",
            "0",
        ])
        .args(["--seed", "11", "--out"])
        .arg(&path)
        .output()
        .expect("run rpkm simulate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&path).expect("the simulated campaign");
    let mut lines: Vec<Vec<u8>> = Vec::new();
    let mut kept: Vec<(String, String, usize)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if n < 2 {
            lines.push(line.as_bytes().to_vec());
            continue;
        }
        let mut fields = line.split(',').skip(1);
        let setup = fields.next().unwrap_or("").to_owned();
        let instrument = fields.next().unwrap_or("").to_owned();
        let first_of_its_instrument = !kept.iter().any(|(_, i, _)| *i == instrument);
        match kept.iter_mut().find(|(s, _, _)| *s == setup) {
            Some((_, _, count)) if *count < 8 => *count += 1,
            None if first_of_its_instrument => kept.push((setup, instrument, 1)),
            Some(_) | None => continue,
        }
        lines.push(line.as_bytes().to_vec());
    }
    let instruments: Vec<&str> = kept.iter().map(|(_, i, _)| i.as_str()).collect();
    assert_eq!(instruments, ["lt", "kgm", "dbb", "self"], "{kept:?}");
    assert_eq!(lines.len(), 2 + 4 * 8);
    let bytes = [lines.join(&b"\n"[..]), b"\n".to_vec()].concat();
    if let Err(e) = Campaign::parse_bytes(&bytes, "base") {
        panic!("the unmutated base is rejected: {e}");
    }
    lines
}

fn set_field(line: &[u8], k: usize, value: &[u8]) -> Vec<u8> {
    let mut fields: Vec<Vec<u8>> = line.split(|&b| b == b',').map(<[u8]>::to_vec).collect();
    let n = fields.len();
    fields[k % n] = value.to_vec();
    fields.join(&b","[..])
}

/// One mutation of `lines` (data rows from index 2; sometimes the header).
fn mutate(lines: &mut [Vec<u8>], rng: &mut Rng) {
    let i = if rng.below(20) == 0 {
        1
    } else {
        2 + rng.below(lines.len() - 2)
    };
    let k = rng.below(18);
    let line = lines[i].clone();
    let value: &[u8] = match rng.below(12) {
        0 => b"nan",
        1 => [&b"inf"[..], b"-inf", b"infinity"][rng.below(3)],
        2 => [&b"1e300"[..], b"-1e300", b"1e17"][rng.below(3)],
        3 => [&b"abc"[..], b"1.2.3", b"0x10", b"--1"][rng.below(4)],
        4 => [&b"true"[..], b"false", b"2"][rng.below(3)],
        5 => b"",
        6 => {
            lines[i] = [&line[..], b",1"].concat();
            return;
        }
        7 => {
            // q1 far beyond the rods, or q2/q3 500 mm from what the rods need
            let q = 4 + [0, 1, 2][rng.below(3)];
            let v = if q == 4 {
                "9000".to_owned()
            } else {
                "3500".to_owned()
            };
            lines[i] = set_field(&line, q, v.as_bytes());
            return;
        }
        8 => {
            let at = rng.below(line.len() + 1);
            lines[i] = [&line[..at], &[0xff, 0xc3][..], &line[at..]].concat();
            return;
        }
        9 => b"-5",
        10 => {
            lines[i] = set_field(&line, 1, b"renamed");
            return;
        }
        _ => b"12,34",
    };
    lines[i] = set_field(&line, k, value);
}

/// The core's judgement of a file read as a stream: every error, in order.
fn judged(bytes: &[u8], label: &str) -> Vec<String> {
    let mut reader = CampaignReader::new(label);
    let mut errors = Vec::new();
    for line in bytes.split(|&b| b == b'\n') {
        if let Err(e) = reader.read_line(line) {
            errors.push(e.to_string());
        }
    }
    if let Err(e) = reader.finish() {
        errors.push(e.to_string());
    }
    errors
}

/// `rpkm node ingest` on `source` (a path, or `stdin` fed `bytes`): its logged rejects.
fn ingest(source: &str, bytes: &[u8], tag: usize) -> Vec<String> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(["node", "ingest", "--source", source, "--backend", "ipc"])
        .args([
            "--ipc-prefix",
            &format!("t_grammar_{}_{tag}", std::process::id()),
        ])
        .args(["--param", "start_delay_s=0", "--param", "exit_at_end=true"])
        .args(["--param", "rate_hz=1e6", "--param", "end_marker=false"])
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("start rpkm node ingest");
    let mut stdin = child.stdin.take().expect("stdin");
    if source == "stdin" {
        stdin.write_all(bytes).expect("feed stdin");
    }
    drop(stdin);
    let out = child.wait_with_output().expect("ingest ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    stderr
        .lines()
        .filter_map(|l| l.strip_prefix("[ingest] rejected: "))
        .map(str::to_owned)
        .collect()
}

#[test]
fn ingest_and_calibrate_reject_the_same_rows_with_the_same_message() {
    let dir = tempfile::tempdir().expect("tempdir");
    let base = base(dir.path());
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut rejected_files, mut rows_rejected, mut calibrated) = (0, 0, 0);
    for n in 0..FILES {
        let mut lines = base.clone();
        for _ in 0..=rng.below(3) {
            mutate(&mut lines, &mut rng);
        }
        let bytes = [lines.join(&b"\n"[..]), b"\n".to_vec()].concat();
        let path = dir.path().join(format!("m{n}.csv"));
        std::fs::write(&path, &bytes).expect("write mutated file");
        let path = path.display().to_string();
        let whole = Campaign::parse_bytes(&bytes, &path)
            .err()
            .map(|e| e.to_string());
        let (label, source) = if n % 2 == 0 {
            (path.as_str(), path.as_str())
        } else {
            ("stdin", "stdin")
        };
        let expected = judged(&bytes, label);
        assert_eq!(
            judged(&bytes, &path).first(),
            whole.as_ref(),
            "file {n}: the whole-file parser stops at the stream's first error"
        );
        let got = ingest(source, &bytes, n);
        assert_eq!(
            got,
            expected,
            "file {n} ({source}):\n{}",
            String::from_utf8_lossy(&bytes)
        );
        let Some(first) = whole else { continue };
        rejected_files += 1;
        rows_rejected += expected.len();
        if n % 2 == 0 && rejected_files % 10 == 1 {
            let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
                .args(["calibrate", &path])
                .output()
                .expect("run rpkm calibrate");
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{stderr}");
            assert_eq!(stderr.trim_end(), format!("error: {first}"));
            assert_eq!(got.first(), Some(&first));
            calibrated += 1;
        }
    }
    eprintln!(
        "{FILES} mutated files: {rejected_files} rejected, {rows_rejected} rejects, \
         {calibrated} also through rpkm calibrate"
    );
    assert!(
        rejected_files > FILES * 3 / 4,
        "mutations too mild: {rejected_files}"
    );
    assert!(calibrated >= 5);
}

//! Property tests of the campaign CSV reader and writer: written campaigns parse back equal,
//! and no input (random bytes, random CSV-like text, mutated valid files) makes the reader
//! panic; it answers `Ok` or a typed error that names the file and a line of the text.

use proptest::prelude::*;
use rpkm_core::campaign::{Campaign, Instrument, MeasuredPose, REQUIRED_COLUMNS};

const FILE: &str = "prop.csv";

/// Finite numbers within |v| <= `limit` (the reader refuses larger ones as beyond any machine),
/// every bit pattern of that range included.
fn within(limit: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -limit..limit,
        1 => (prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO)
            .prop_map(move |v| v % limit),
        1 => Just(0.0),
    ]
}

/// Actuator positions of a pose of the nominal machine in the spec's workspace, q2 and q3 off
/// by up to 50 mm (the reader refuses poses the rods cannot close).
fn reachable_q() -> impl Strategy<Value = [f64; 4]> {
    (
        -150.0..150.0f64,
        700.0..2700.0f64,
        -50.0..50.0f64,
        -50.0..50.0f64,
    )
        .prop_map(|(x, y, d2, d3)| {
            let p = rpkm_core::params::Params::nominal();
            let s = rpkm_core::geometry::igm(&p, rpkm_core::params::Model::M24, x, y)
                .expect("the workspace is reachable");
            let q = s.q();
            [q[0], q[1] + d2, q[2] + d3, q[3]]
        })
}

/// Raw material of one row; the campaign strategy makes it consistent with its setup.
#[derive(Debug, Clone)]
struct RawRow {
    t: f64,
    q: [f64; 4],
    f: [f64; 4],
    follower: u8,
    measured: [f64; 4],
    reset_blank: [bool; 4],
    covariates: Vec<Option<f64>>,
}

fn raw_row() -> impl Strategy<Value = RawRow> {
    (
        within(1e10),
        reachable_q(),
        prop::array::uniform4(within(1e6)),
        0u8..16,
        // measured x, y, r, psi: within psi's bound, a full turn
        prop::array::uniform4(within(std::f64::consts::TAU)),
        prop::array::uniform4(any::<bool>()),
        prop::collection::vec(prop::option::of(within(1e10)), 3),
    )
        .prop_map(
            |(t, q, f, follower, measured, reset_blank, covariates)| RawRow {
                t,
                q,
                f,
                follower,
                measured,
                reset_blank,
                covariates,
            },
        )
}

fn instrument() -> impl Strategy<Value = Instrument> {
    prop::sample::select(Instrument::ALL.to_vec())
}

/// A campaign that `validate` accepts and whose strings are writable.
fn campaign() -> impl Strategy<Value = Campaign> {
    (
        prop::collection::vec("[^\n\r]{0,16}", 0..3),
        prop::collection::vec("[a-z0-9_]{0,5}", 0..3),
        prop::collection::vec(
            (
                "[A-Za-z_.-]{0,5}",
                instrument(),
                any::<bool>(),
                prop::collection::vec(raw_row(), 1..5),
            ),
            1..5,
        ),
    )
        .prop_map(|(comments, covariate_suffixes, setups)| {
            let covariate_names: Vec<String> = covariate_suffixes
                .iter()
                .enumerate()
                .map(|(k, s)| format!("c{k}{s}"))
                .collect();
            let mut poses = Vec::new();
            for (k, (prefix, instrument, circle_reset, rows)) in setups.into_iter().enumerate() {
                let m = instrument.measures();
                let mask = [m.x, m.y, m.r, m.psi];
                for (j, row) in rows.into_iter().enumerate() {
                    let reset = j == 0
                        && (instrument.is_relative()
                            || (instrument == Instrument::Circle && circle_reset));
                    let value = |i: usize| {
                        let on = mask.get(i).copied().unwrap_or(false);
                        let blank = row.reset_blank.get(i).copied().unwrap_or(false);
                        let v = row.measured.get(i).copied().unwrap_or(0.0);
                        match (on, reset, blank) {
                            (false, _, _) | (true, true, true) => None,
                            (true, true, false) => Some(0.0),
                            (true, false, _) => Some(v),
                        }
                    };
                    let mut follower = [0, 1, 2, 3].map(|b| row.follower & (1 << b) != 0);
                    if instrument == Instrument::SelfCal {
                        follower[1] = true;
                        follower[2] = true;
                    }
                    poses.push(MeasuredPose {
                        t: row.t,
                        setup: format!("{prefix}{k}"),
                        instrument,
                        reset,
                        q: row.q,
                        f: row.f,
                        follower,
                        x: value(0),
                        y: value(1),
                        r: value(2),
                        psi: value(3),
                        covariates: row.covariates[..covariate_names.len()].to_vec(),
                        line: 0,
                    });
                }
            }
            // Monotonic time, and the lines `to_csv` writes the rows on.
            let mut ts: Vec<f64> = poses.iter().map(|p| p.t).collect();
            ts.sort_by(f64::total_cmp);
            for (i, (pose, t)) in poses.iter_mut().zip(ts).enumerate() {
                pose.t = t;
                pose.line = comments.len() + 2 + i;
            }
            Campaign {
                source: FILE.to_owned(),
                comments,
                covariate_names,
                poses,
            }
        })
}

/// The reader's contract on any text: no panic; an error names the file and a line of the
/// text; an accepted campaign is stable under write-and-read.
fn check_any(text: &str) {
    match Campaign::parse(text, FILE) {
        Ok(c) => {
            assert!(c.validate().is_ok(), "accepted but invalid: {c:?}");
            let once = Campaign::parse(&c.to_csv(), FILE).expect("written campaign parses");
            let twice = Campaign::parse(&once.to_csv(), FILE).expect("written campaign parses");
            assert_eq!(once, twice);
        }
        Err(e) => {
            assert_eq!(e.file(), FILE);
            let message = e.to_string();
            assert!(message.starts_with(FILE), "{message}");
            if let Some(line) = e.line() {
                let lines = text.lines().count();
                assert!(
                    (1..=lines).contains(&line),
                    "line {line} of {lines}: {message}"
                );
            }
        }
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    DeleteChar(usize),
    InsertChar(usize, char),
    DeleteLine(usize),
    DuplicateLine(usize),
    SwapLines(usize, usize),
    ReplaceField(usize, usize, String),
    DeleteField(usize, usize),
    DuplicateField(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let field_text = prop_oneof![
        Just(String::new()),
        Just("NaN".to_owned()),
        Just("inf".to_owned()),
        Just("1e999".to_owned()),
        Just("0".to_owned()),
        Just("1".to_owned()),
        Just("23".to_owned()),
        Just("lt".to_owned()),
        Just("self".to_owned()),
        Just("#".to_owned()),
        "[-+0-9.eE]{1,8}",
        ".{0,6}",
    ];
    prop_oneof![
        any::<usize>().prop_map(Mutation::DeleteChar),
        (
            any::<usize>(),
            prop_oneof![Just(','), Just('\n'), Just('#'), Just('-'), any::<char>()]
        )
            .prop_map(|(i, c)| Mutation::InsertChar(i, c)),
        any::<usize>().prop_map(Mutation::DeleteLine),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
        (any::<usize>(), any::<usize>(), field_text)
            .prop_map(|(l, f, s)| Mutation::ReplaceField(l, f, s)),
        (any::<usize>(), any::<usize>()).prop_map(|(l, f)| Mutation::DeleteField(l, f)),
        (any::<usize>(), any::<usize>()).prop_map(|(l, f)| Mutation::DuplicateField(l, f)),
    ]
}

fn apply(text: &str, mutation: &Mutation) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let n = lines.len().max(1);
    let edit_fields =
        |lines: &mut Vec<String>, l: usize, edit: &dyn Fn(&mut Vec<String>, usize)| {
            if let Some(line) = lines.get_mut(l % n) {
                let mut fields: Vec<String> = line.split(',').map(str::to_owned).collect();
                let k = fields.len();
                edit(&mut fields, k);
                *line = fields.join(",");
            }
        };
    match mutation {
        Mutation::DeleteChar(i) => {
            let mut chars: Vec<char> = text.chars().collect();
            if !chars.is_empty() {
                let k = i % chars.len();
                chars.remove(k);
            }
            return chars.into_iter().collect();
        }
        Mutation::InsertChar(i, c) => {
            let mut chars: Vec<char> = text.chars().collect();
            let k = i % (chars.len() + 1);
            chars.insert(k, *c);
            return chars.into_iter().collect();
        }
        Mutation::DeleteLine(l) => {
            if !lines.is_empty() {
                lines.remove(l % n);
            }
        }
        Mutation::DuplicateLine(l) => {
            if let Some(line) = lines.get(l % n).cloned() {
                lines.insert(l % n, line);
            }
        }
        Mutation::SwapLines(a, b) => {
            if !lines.is_empty() {
                lines.swap(a % n, b % n);
            }
        }
        Mutation::ReplaceField(l, f, s) => {
            edit_fields(&mut lines, *l, &|fields, k| fields[f % k].clone_from(s));
        }
        Mutation::DeleteField(l, f) => edit_fields(&mut lines, *l, &|fields, k| {
            fields.remove(f % k);
        }),
        Mutation::DuplicateField(l, f) => edit_fields(&mut lines, *l, &|fields, k| {
            let v = fields[f % k].clone();
            fields.insert(f % k, v);
        }),
    }
    lines.into_iter().map(|l| l + "\n").collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn written_campaigns_parse_back_equal(c in campaign()) {
        prop_assert!(c.validate().is_ok(), "{:?}", c.validate());
        let text = c.to_csv();
        let back = Campaign::parse(&text, FILE);
        prop_assert_eq!(back.as_ref(), Ok(&c), "{}", text);
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        check_any(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn csv_like_text_never_panics(body in "[0-9a-z_,.#\n +-]{0,400}", with_header in any::<bool>()) {
        let text = if with_header {
            format!("{}\n{body}", REQUIRED_COLUMNS.join(","))
        } else {
            body
        };
        check_any(&text);
    }

    #[test]
    fn mutated_valid_files_never_panic(
        c in campaign(),
        mutations in prop::collection::vec(mutation(), 1..5),
    ) {
        let mut text = c.to_csv();
        for m in &mutations {
            text = apply(&text, m);
        }
        check_any(&text);
    }
}

//! The reference bags of `bags/` against independent truth:
//! - `calibration` and `calibration_val` rebuild `bags/demo/campaign.csv` and
//!   `campaign.val.csv` (the demo's CSV data, made by the same twin command);
//! - `stream_8khz`: the encoders of the holding drives read the controller's igm of the
//!   programmed circle, the followers read the true machine's rgm (core geometry with the true
//!   parameters of the truth file), the TCP stays on the circle;
//! - `preload_fault`: the drive forces are the core elastic model's at the true parameters with
//!   q3's carrier drifted by the ramp of the truth file, and cross 100 % current;
//! - every message of every reference bag decodes to the same values in `mcap_ros2` and
//!   `rosbags` (Python, `tests/python/bag_check.py`) as in our reader.
//!
//! Re-mint the bags with the commands of `bags/README.md` after a change of the twin.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use crate::bag_support;

use std::path::Path;
use std::process::Command;

use bag_support::*;
use rpkm_core::campaign::Campaign;
use rpkm_core::elastic::{self, Stiffness, ALL_ACTIVE, NOMINAL_DRIVE_FORCE_N};
use rpkm_core::geometry;
use rpkm_core::params::{self, Model, Params};
use rpkm_msgs::ActuatorState;
use rpkm_nodes::campaign_bag::{read_campaign, seconds_from_stamp};
use rpkm_transport::bag::BagReader;
use serde_json::Value;

const BAGS: [&str; 4] = [
    "calibration",
    "calibration_val",
    "stream_8khz",
    "preload_fault",
];

fn truth(name: &str) -> Value {
    let path = reference_bag(&format!("{name}.truth.json"));
    serde_json::from_str(&std::fs::read_to_string(&path).expect("truth file")).expect("JSON")
}

/// The parameter set `key` (`params`: the true machine; `controller`: what the controller
/// commands igm with) of a truth file.
fn truth_params(truth: &Value, key: &str) -> Params {
    let mut p = Params::nominal();
    for (name, v) in truth[key].as_object().expect("parameter set") {
        let i = params::index_of(name).unwrap_or_else(|| panic!("unknown parameter {name}"));
        p[i] = v.as_f64().expect("number");
    }
    p
}

fn parse_csv(path: &Path) -> Campaign {
    let text = std::fs::read_to_string(path).expect("read csv");
    Campaign::parse(&text, &path.display().to_string()).expect("parse csv")
}

fn same_but_units(a: f64, b: f64) -> bool {
    (a - b).abs() <= 4.0 * f64::EPSILON * a.abs().max(b.abs())
}

fn assert_same_campaign(bag: &str, csv: &str) {
    let reader = BagReader::open(reference_bag(bag)).expect("open bag");
    let from_bag = read_campaign(&reader).expect("campaign from bag");
    let from_csv = parse_csv(&reference_bag(csv));
    assert_eq!(from_bag.covariate_names, from_csv.covariate_names);
    assert_eq!(from_bag.comments, from_csv.comments);
    assert_eq!(from_bag.poses.len(), from_csv.poses.len(), "{bag}: poses");
    for (a, b) in from_bag.poses.iter().zip(&from_csv.poses) {
        let at = format!("{csv}:{}", b.line);
        assert_eq!(
            (a.t, &a.setup, a.instrument, a.reset),
            (b.t, &b.setup, b.instrument, b.reset),
            "{at}"
        );
        assert_eq!((a.f, a.follower, a.psi), (b.f, b.follower, b.psi), "{at}");
        assert_eq!(a.covariates, b.covariates, "{at}");
        let mm = |v: Option<f64>| v.unwrap_or(0.0);
        for (x, y) in a.q.iter().zip(&b.q).chain(
            [(mm(a.x), mm(b.x)), (mm(a.y), mm(b.y)), (mm(a.r), mm(b.r))]
                .iter()
                .map(|(x, y)| (x, y)),
        ) {
            assert!(same_but_units(*x, *y), "{at}: {x} vs {y}");
        }
        assert_eq!(
            (a.x.is_some(), a.y.is_some(), a.r.is_some()),
            (b.x.is_some(), b.y.is_some(), b.r.is_some()),
            "{at}"
        );
    }
}

#[test]
fn calibration_bag_is_the_demo_campaign() {
    assert_same_campaign("calibration", "demo/campaign.csv");
    assert_same_campaign("calibration_val", "demo/campaign.val.csv");
    assert_eq!(truth("calibration"), {
        let text = std::fs::read_to_string(reference_bag("demo/truth.json")).expect("demo truth");
        serde_json::from_str::<Value>(&text).expect("JSON")
    });
}

/// Programmed TCP of stream sample `k`, mm: the circle of the truth's stream description.
fn circle_target(stream: &Value, k: usize) -> (f64, f64) {
    assert_eq!(stream["motion"], "circle");
    let hz = stream["hz"].as_f64().expect("hz");
    let a = std::f64::consts::TAU * (k as f64 / hz) / 2.0;
    (100.0 * a.cos(), 1700.0 + 100.0 * a.sin())
}

#[test]
fn stream_bag_follows_the_core_geometry() {
    let truth = truth("stream_8khz");
    let stream = &truth["stream"];
    let p_true = truth_params(&truth, "params");
    let controller = truth_params(&truth, "controller");
    let states: Vec<ActuatorState> =
        decode_all(&reference_bag("stream_8khz"), "/rpkm/actuator_state");
    assert_eq!(states.len(), 4000);
    let start = stream["start_s"].as_f64().expect("start");
    for (k, s) in states.iter().enumerate() {
        assert_eq!(s.seq, k as u64);
        let t = seconds_from_stamp(s.stamp);
        assert!(
            (t - (start + k as f64 / 8000.0)).abs() < 1e-9,
            "sample {k}: t {t}"
        );
        assert_eq!(s.follower, [false, true, true, false]);
        assert_eq!(s.force, [0.0; 4], "rigid machine, followers: no preload");
        let q = s.position.map(|v| v * 1000.0);
        // Holding drives read the command: the controller's igm of the programmed point.
        let (x, y) = circle_target(stream, k);
        let cmd = geometry::igm(&controller, Model::M29, x, y)
            .expect("igm")
            .q();
        for i in [0, 3] {
            assert!(
                (q[i] - cmd[i]).abs() < 1e-9,
                "sample {k}: q{} {} vs command {}",
                i + 1,
                q[i],
                cmd[i]
            );
        }
        // Followers read the true machine: rgm with the true parameters, within the encoder
        // noise (0.2 µm on each reading and on the carriers).
        let [q2, q3] = geometry::rgm(&p_true, Model::M29, q[0], q[3]).expect("rgm");
        assert!(
            (q[1] - q2).abs() < 3e-3,
            "sample {k}: q2 {} vs rgm {q2}",
            q[1]
        );
        assert!(
            (q[2] - q3).abs() < 3e-3,
            "sample {k}: q3 {} vs rgm {q3}",
            q[2]
        );
        // The TCP is on the programmed circle but for the controller's parameter error.
        let tcp = geometry::fgm(&p_true, Model::M29, q[0], q[3]).expect("fgm");
        let r = (tcp.x().powi(2) + (tcp.y() - 1700.0).powi(2)).sqrt();
        assert!((r - 100.0).abs() < 1.0, "sample {k}: radius {r}");
        let temp = s.covariates()[0];
        assert!(
            (temp - 20.0).abs() < 0.05,
            "sample {k}: temp_machine {temp}"
        );
    }
}

#[test]
fn preload_fault_bag_matches_the_elastic_model() {
    let truth = truth("preload_fault");
    let stream = &truth["stream"];
    assert_eq!(stream["motion"], "hold");
    assert_eq!(stream["fault"]["drive"], 2, "the fault is on q3");
    let max_mm = stream["fault"]["max_mm"].as_f64().expect("max_mm");
    let p_true = truth_params(&truth, "params");
    let stiffness: Stiffness =
        serde_json::from_value(truth["stiffness"].clone()).expect("stiffness");
    let states: Vec<ActuatorState> =
        decode_all(&reference_bag("preload_fault"), "/rpkm/actuator_state");
    let n = states.len();
    assert_eq!(n, 2000);
    let controller = truth_params(&truth, "controller");
    let cmd = geometry::igm(&controller, Model::M29, 0.0, 1700.0)
        .expect("igm")
        .q();
    for k in (0..n).step_by(50).chain([n - 1]) {
        let s = &states[k];
        assert_eq!(
            s.follower, [false; 4],
            "all drives hold under preload_elastic"
        );
        let mut carriers = cmd;
        carriers[2] += max_mm * k as f64 / (n - 1) as f64;
        let eq = elastic::fegm(&p_true, &stiffness, carriers, ALL_ACTIVE).expect("fegm");
        for i in 0..4 {
            // 0.2 µm of encoder noise on the carriers is about 20-40 N.
            assert!(
                (s.force[i] - eq.drive_force[i]).abs() < 150.0,
                "sample {k}: f{} {} N vs elastic model {} N",
                i + 1,
                s.force[i],
                eq.drive_force[i]
            );
        }
    }
    let current = |s: &ActuatorState| s.force[2].abs() / NOMINAL_DRIVE_FORCE_N * 100.0;
    assert!(
        current(&states[0]) < 50.0,
        "q3 starts below 50 %: {}",
        current(&states[0])
    );
    assert!(
        current(&states[n - 1]) > 150.0,
        "q3 ends past 150 %: {}",
        current(&states[n - 1])
    );
}

/// Our reader's view of a bag, as bag_check.py prints it.
fn our_messages(bag: &Path) -> Vec<(String, String, u64, Value)> {
    let reader = BagReader::open(bag).expect("open");
    reader
        .messages()
        .map(|m| {
            let m = m.expect("read");
            let value = rpkm_nodes::topics::decode_json(m.type_name, &m.data)
                .unwrap_or_else(|| panic!("type {} unknown to rpkm", m.type_name))
                .unwrap_or_else(|e| panic!("{}: {e}", m.topic));
            (
                m.topic.to_owned(),
                m.type_name.to_owned(),
                m.log_time,
                value,
            )
        })
        .collect()
}

/// Ties of log time (a pose's state and measurement) may come in either order.
fn normalise(mut v: Vec<(String, String, u64, Value)>) -> Vec<(String, String, u64, Value)> {
    v.sort_by(|a, b| (a.2, &a.0).cmp(&(b.2, &b.0)));
    v
}

#[test]
fn python_readers_decode_every_reference_bag_alike() {
    let Some(python) = python() else {
        println!("skipped: no .venv (python3 -m venv .venv && .venv/bin/pip install -r tests/python/requirements.txt)");
        return;
    };
    let script = repo_root().join("tests/python/bag_check.py");
    for name in BAGS {
        let bag = reference_bag(name);
        let output = Command::new(&python)
            .arg(&script)
            .arg(&bag)
            .output()
            .expect("run bag_check.py");
        assert!(
            output.status.success(),
            "bag_check.py {name}:\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let result: Value = serde_json::from_slice(&output.stdout).expect("JSON");
        let ours = normalise(our_messages(&bag));
        assert!(!ours.is_empty(), "{name}: empty");
        for reader in ["mcap_ros2", "rosbags"] {
            let theirs = normalise(
                result[reader]
                    .as_array()
                    .unwrap_or_else(|| panic!("{reader}: no list"))
                    .iter()
                    .map(|m| {
                        (
                            m["topic"].as_str().unwrap_or_default().to_owned(),
                            m["type"].as_str().unwrap_or_default().to_owned(),
                            m["log_time"].as_u64().unwrap_or_default(),
                            m["value"].clone(),
                        )
                    })
                    .collect(),
            );
            assert_eq!(theirs.len(), ours.len(), "{name}, {reader}: message count");
            for (i, (t, o)) in theirs.iter().zip(&ours).enumerate() {
                assert_eq!(t, o, "{name}, {reader}: message {i} differs");
            }
        }
    }
}

/// One line of `bags/recipes.txt`: what `bags/regenerate.sh` runs.
struct Recipe {
    out: String,
    truth: String,
    args: Vec<String>,
}

fn recipes() -> Vec<Recipe> {
    let path = reference_bag("recipes.txt");
    let text = std::fs::read_to_string(&path).expect("bags/recipes.txt");
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let mut words = l.split_whitespace().map(str::to_owned);
            let (out, truth) = (words.next(), words.next());
            Recipe {
                out: out.expect("OUT"),
                truth: truth.expect("TRUTH"),
                args: words.collect(),
            }
        })
        .collect()
}

/// What a bag's format is: its metadata.yaml (counts and times are the recipe's, so the
/// whole text), and per topic its type, encodings, schema, QoS, type hash and message count;
/// not the values the messages carry.
fn bag_format(bag: &Path) -> (String, Vec<String>) {
    let metadata = std::fs::read_to_string(bag.join("metadata.yaml")).expect("metadata.yaml");
    let reader = BagReader::open(bag).expect("open bag");
    let topics = reader
        .topics()
        .iter()
        .map(|t| {
            format!(
                "{} {} {} {} {:?} {} {:?} {}",
                t.name,
                t.type_name,
                t.message_encoding,
                t.schema_encoding,
                t.definition,
                t.offered_qos_profiles,
                t.type_hash,
                t.message_count
            )
        })
        .collect();
    (metadata, topics)
}

/// A CSV campaign's format: its header, and each row's setup, instrument, reset and which
/// columns are filled (not the values).
fn csv_format(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).expect("campaign CSV");
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            if l.starts_with("t,") {
                return l.to_owned();
            }
            let cells: Vec<&str> = l.split(',').collect();
            let filled: String = cells
                .iter()
                .map(|c| if c.is_empty() { '.' } else { 'x' })
                .collect();
            format!("{} {}", cells[1..4].join(","), filled)
        })
        .collect()
}

/// Every committed artefact of bags/ is what today's writer writes from its recipe: a
/// format change of the writer (a new metadata key, a QoS depth, a schema) must re-mint them
/// (`bags/regenerate.sh`), or readers of the committed bags test yesterday's format.
#[test]
fn committed_bags_are_what_the_writer_writes_from_their_recipes() {
    let dir = scratch("fresh-from-recipes");
    let all = recipes();
    assert_eq!(all.len(), 5, "bags/recipes.txt");
    for r in &all {
        let fresh = dir.join(&r.out);
        std::fs::create_dir_all(fresh.parent().expect("parent")).expect("dir");
        run_ok(
            rpkm()
                .arg("simulate")
                .args(&r.args)
                .arg("--out")
                .arg(&fresh)
                .arg("--truth")
                .arg(dir.join(&r.truth)),
        );
        let committed = reference_bag(&r.out);
        if let Some(stem) = r.out.strip_suffix(".csv") {
            for suffix in [".csv", ".val.csv"] {
                let (c, f) = (
                    reference_bag(&format!("{stem}{suffix}")),
                    dir.join(format!("{stem}{suffix}")),
                );
                assert_eq!(csv_format(&c), csv_format(&f), "{}", c.display());
            }
            continue;
        }
        let mut bags = vec![(committed, fresh)];
        let val = reference_bag(&format!("{}_val", r.out));
        if val.exists() {
            bags.push((val, dir.join(format!("{}_val", r.out))));
        }
        for (c, f) in bags {
            let (cm, ct) = bag_format(&c);
            let (fm, ft) = bag_format(&f);
            assert_eq!(
                cm,
                fm,
                "{}/metadata.yaml: re-mint with bags/regenerate.sh",
                c.display()
            );
            assert_eq!(ct, ft, "{}: topics differ from a fresh bag", c.display());
        }
    }
}

//! Bags that `ros2 bag info/play` open on Iron and Jazzy. tests/cpp/rosbag2_metadata_check.cpp
//! reads a bag's `metadata.yaml` with yaml-cpp by rosbag2's own decode steps, once as Jazzy
//! and once as Iron (QoS profiles included, as each one's player decodes them), and compares
//! every map's keys with the ones rosbag2 writes. tests/python/mcap_metadata_check.py compares
//! the metadata with what rosbag2's MCAP storage derives from the file itself.
//!
//! Every bag rpkm writes (simulate with a stream, ingest, recover) and the reference bags must
//! pass both; the checker must refuse what rosbag2 refuses (edited copies), and accept the
//! bags another rosbag2-compatible writer (rosbags) produces, in version 8 and 9 alike, which
//! rpkm must read too. Version 9 is refused by Iron, which is why rpkm writes version 8.

use crate::bag_support;

use bag_support::{python, reference_bag, repo_root, rpkm, run_ok, scratch};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The checker compiled with g++ against yaml-cpp, once for all tests of this file; `None`
/// skips where yaml-cpp is missing, except in CI (`RPKM_REQUIRE_PYTHON`, set by .ci/run,
/// which installs libyaml-cpp-dev).
fn checker() -> Option<PathBuf> {
    static CHECKER: OnceLock<Option<PathBuf>> = OnceLock::new();
    CHECKER.get_or_init(compile_checker).clone()
}

fn compile_checker() -> Option<PathBuf> {
    let have = Path::new("/usr/include/yaml-cpp/yaml.h").is_file()
        && Command::new("g++").arg("--version").output().is_ok();
    if !have {
        assert!(
            std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
            "CI: g++ and libyaml-cpp-dev are required (.ci/run installs them)"
        );
        eprintln!("SKIPPED: g++ or yaml-cpp (libyaml-cpp-dev) not found");
        return None;
    }
    let out = scratch("mdcheck").join("rosbag2_metadata_check");
    let src = repo_root().join("tests/cpp/rosbag2_metadata_check.cpp");
    let status = Command::new("g++")
        .args(["-std=c++17", "-O1", "-o"])
        .arg(&out)
        .arg(&src)
        .arg("-lyaml-cpp")
        .status()
        .expect("g++ runs");
    assert!(status.success(), "the checker does not compile");
    Some(out)
}

/// The checker's verdict: its exit code and its lines.
struct Verdict {
    code: Option<i32>,
    lines: Vec<String>,
}

impl Verdict {
    fn line(&self, prefix: &str) -> &str {
        self.lines
            .iter()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("no {prefix} line in {:?}", self.lines))
    }
}

fn check(checker: &Path, bag: &Path) -> Verdict {
    let out = Command::new(checker)
        .arg(bag)
        .output()
        .expect("checker runs");
    Verdict {
        code: out.status.code(),
        lines: String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(str::to_owned)
            .collect(),
    }
}

/// Bags written by every rpkm command that writes one, in `dir`.
fn bags_rpkm_writes(dir: &Path) -> Vec<PathBuf> {
    let (sim, ingested, cut, fixed) = (
        dir.join("sim"),
        dir.join("ingested"),
        dir.join("cut"),
        dir.join("fixed"),
    );
    run_ok(
        rpkm()
            .args(["simulate", "--campaign", "lt", "--validation", "0"])
            .args(["--stream-hz", "1000", "--stream-seconds", "0.2", "--out"])
            .arg(&sim),
    );
    let csv = dir.join("campaign.csv");
    run_ok(
        rpkm()
            .args(["bag", "campaign"])
            .arg(&sim)
            .arg("--out")
            .arg(&csv),
    );
    run_ok(rpkm().arg("ingest").arg(&csv).arg("--out").arg(&ingested));
    // a recorder that died before writing metadata.yaml: `rpkm bag recover` writes it
    std::fs::create_dir_all(&cut).expect("dir");
    std::fs::copy(sim.join("sim_0.mcap"), cut.join("cut_0.mcap")).expect("copy");
    run_ok(
        rpkm()
            .args(["bag", "recover"])
            .arg(&cut)
            .arg("--out")
            .arg(&fixed),
    );
    vec![sim, ingested, fixed]
}

#[test]
fn ros2_bag_on_iron_and_jazzy_reads_every_bag_rpkm_writes() {
    let Some(checker) = checker() else { return };
    let dir = scratch("rosbag2-metadata");
    let mut bags = bags_rpkm_writes(&dir);
    for name in [
        "calibration",
        "calibration_val",
        "stream_8khz",
        "preload_fault",
    ] {
        bags.push(reference_bag(name));
    }
    for bag in &bags {
        let v = check(&checker, bag);
        let all = format!("{}: {:?}", bag.display(), v.lines);
        assert_eq!(v.code, Some(0), "{all}");
        // three topics, and the Parameters where the twin recorded them (preload_fault)
        let topics = rpkm_transport::bag::BagReader::open(bag)
            .expect("the bag opens")
            .topics()
            .len();
        assert!(
            v.line("version ")
                .starts_with(&format!("version 8 topics {topics} ")),
            "{all}"
        );
        assert!((3..=4).contains(&topics), "{all}");
        assert_eq!(v.line("jazzy: "), "jazzy: ok", "{all}");
        assert_eq!(v.line("iron: "), "iron: ok", "{all}");
        assert_eq!(v.line("keys: "), "keys: as rosbag2 writes them", "{all}");
    }
    // 200 stream samples at 1 kHz, 45 poses (1 state + 1 measurement each), 1 campaign info
    let sim = check(&checker, &bags[0]);
    assert_eq!(
        sim.line("version "),
        "version 8 topics 3 messages 291 files 1"
    );
}

/// The fresh bag's metadata.yaml with each `(from, to)` of `edits` applied once, as a bag
/// folder of its own.
fn edited(dir: &Path, fresh: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(fresh.join("metadata.yaml")).expect("metadata");
    for (from, to) in edits {
        assert!(text.contains(from), "{from:?} not in the metadata");
        text = text.replacen(from, to, 1);
    }
    let copy = dir.join(name);
    std::fs::create_dir_all(&copy).expect("dir");
    std::fs::write(copy.join("metadata.yaml"), text).expect("write");
    copy
}

/// An edit of a good metadata.yaml and the starts of the checker's three verdicts.
struct Refusal {
    edits: &'static [(&'static str, &'static str)],
    jazzy: &'static str,
    iron: &'static str,
    keys: &'static str,
}

const ROOT: &str = "rosbag2_bagfile_information";
const TOPIC0: &str = "rosbag2_bagfile_information.topics_with_message_count[0].topic_metadata";

fn refusals() -> Vec<Refusal> {
    vec![
        // the bug of issue 12: Iron and Jazzy stop at "invalid node"
        Refusal {
            edits: &[("  custom_data: null\n", "")],
            jazzy: "refused: ROOT.custom_data: invalid node; first invalid key: \"custom_data\"",
            iron: "refused: ROOT.custom_data: invalid node",
            keys: "ROOT: no custom_data",
        },
        // required from version 8 on, by Jazzy only
        Refusal {
            edits: &[("  ros_distro: ''\n", "")],
            jazzy: "refused: ROOT.ros_distro: invalid node",
            iron: "ok",
            keys: "ROOT: no ros_distro",
        },
        // a version-8 QoS string with rmw's names: Jazzy tells the forms apart, Iron's player
        // wants integers
        Refusal {
            edits: &[
                ("history: 1\n", "history: keep_last\n"),
                ("reliability: 1\n", "reliability: reliable\n"),
                ("durability: 1\n", "durability: transient_local\n"),
                ("liveliness: 1\n", "liveliness: automatic\n"),
            ],
            jazzy: "ok",
            iron: "refused: TOPIC0.offered_qos_profiles[0].history: yaml-cpp: error at line 1",
            keys: "as rosbag2 writes them",
        },
        // half of each: the names are not rmw's
        Refusal {
            edits: &[("history: 1\n", "history: keep_last\n")],
            jazzy: "refused: TOPIC0.offered_qos_profiles[0].reliability: unknown policy 1",
            iron: "refused: TOPIC0.offered_qos_profiles[0].history",
            keys: "as rosbag2 writes them",
        },
        Refusal {
            edits: &[("      type_description_hash: ''\n", "")],
            jazzy: "refused: TOPIC0.type_description_hash: invalid node",
            iron: "refused: TOPIC0.type_description_hash: invalid node",
            keys: "TOPIC0: no type_description_hash",
        },
        Refusal {
            edits: &[(
                "  compression_mode: ''\n",
                "  compression_mode: ''\n  bag_size: 1\n",
            )],
            jazzy: "ok",
            iron: "ok",
            keys: "ROOT: bag_size (rosbag2 has none)",
        },
        Refusal {
            edits: &[("nanoseconds_since_epoch: ", "nanoseconds_since_epoch: -")],
            jazzy: "refused: ROOT.starting_time.nanoseconds_since_epoch: yaml-cpp: error at",
            iron: "refused: ROOT.starting_time.nanoseconds_since_epoch: yaml-cpp: error at",
            keys: "as rosbag2 writes them",
        },
    ]
}

#[test]
fn the_checker_refuses_what_rosbag2_refuses() {
    let Some(checker) = checker() else { return };
    let dir = scratch("rosbag2-refusals");
    let fresh = dir.join("fresh");
    run_ok(
        rpkm()
            .args(["simulate", "--campaign", "lt", "--validation", "0", "--out"])
            .arg(&fresh),
    );
    let expand = |s: &str| s.replace("TOPIC0", TOPIC0).replace("ROOT", ROOT);
    for (i, case) in refusals().into_iter().enumerate() {
        let v = check(
            &checker,
            &edited(&dir, &fresh, &format!("e{i}"), case.edits),
        );
        let all = format!("edits {:?}: {:?}", case.edits, v.lines);
        assert_eq!(v.code, Some(1), "{all}");
        let verdicts = [
            ("jazzy: ", case.jazzy),
            ("iron: ", case.iron),
            ("keys: ", case.keys),
        ];
        for (prefix, expected) in verdicts {
            let line = v.line(prefix);
            assert!(line[prefix.len()..].starts_with(&expand(expected)), "{all}");
        }
    }
}

fn python_json(py: &Path, script: &str, args: &[&Path]) -> serde_json::Value {
    let out = Command::new(py)
        .arg(repo_root().join("tests/python").join(script))
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

#[test]
fn metadata_says_what_rosbag2_derives_from_the_mcap_file() {
    let Some(py) = python() else {
        eprintln!("SKIPPED: no .venv (tests/python/requirements.txt)");
        return;
    };
    let dir = scratch("rosbag2-storage");
    let mut bags = bags_rpkm_writes(&dir);
    bags.push(reference_bag("preload_fault"));
    for bag in &bags {
        let report = python_json(&py, "mcap_metadata_check.py", &[bag]);
        assert_eq!(
            report["mismatches"],
            serde_json::json!([]),
            "{}",
            bag.display()
        );
        // the bag's three fields, and five of each topic (a bag of Parameters has four topics)
        let metadata = std::fs::read_to_string(bag.join("metadata.yaml")).expect("metadata.yaml");
        let topics = metadata.matches("topic_metadata:").count();
        assert!(topics >= 3, "{}: {topics} topics", bag.display());
        assert_eq!(report["compared"], 3 + 5 * topics, "{}", bag.display());
    }
    // and it notices a count that is not the file's
    let wrong = edited(
        &dir,
        &bags[0],
        "wrong",
        &[("message_count: 291\n", "message_count: 290\n")],
    );
    std::fs::copy(bags[0].join("sim_0.mcap"), wrong.join("sim_0.mcap")).expect("copy");
    let report = python_json(&py, "mcap_metadata_check.py", &[&wrong]);
    assert_eq!(
        report["mismatches"],
        serde_json::json!(["message_count: metadata.yaml 290, MCAP file 291"])
    );
}

#[test]
fn bags_another_rosbag2_writer_produces_pass_the_checker_and_rpkm_reads_them() {
    let Some(py) = python() else {
        eprintln!("SKIPPED: no .venv (tests/python/requirements.txt)");
        return;
    };
    let Some(checker) = checker() else { return };
    let dir = scratch("rosbags-written");
    for version in ["8", "9"] {
        let bag = dir.join(format!("v{version}"));
        let out = Command::new(&py)
            .arg(repo_root().join("tests/python/rosbags_write.py"))
            .arg(&bag)
            .arg(version)
            .output()
            .expect("python runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v = check(&checker, &bag);
        let all = format!("version {version}: {:?}", v.lines);
        assert_eq!(v.line("jazzy: "), "jazzy: ok", "{all}");
        assert_eq!(v.line("keys: "), "keys: as rosbag2 writes them", "{all}");
        let iron = v.line("iron: ");
        if version == "8" {
            assert_eq!(iron, "iron: ok", "{all}");
        } else {
            // Iron reads offered_qos_profiles as a string from version 4 on
            assert!(
                iron.starts_with("iron: refused: rosbag2_bagfile_information.topics_with_message_count[0].topic_metadata.offered_qos_profiles: yaml-cpp: error at line"),
                "{all}"
            );
        }
        let info = run_ok(rpkm().args(["bag", "info"]).arg(&bag));
        assert!(
            info.lines()
                .any(|l| l.split_whitespace().collect::<Vec<_>>()
                    == [
                        "/chatter",
                        "3",
                        "msgs",
                        "1000000000.0",
                        "Hz",
                        "std_msgs/msg/String"
                    ]),
            "{info}"
        );
    }
}

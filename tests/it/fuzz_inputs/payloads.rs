//! Parameter maps where values belong, bags with corrupt payloads, validation campaigns with a
//! reading moved.

use super::harness::{family, judge, keep, mutate_text, rpkm, run, scratch, simulated_lt_campaign};
use crate::fuzz_support::Rng;
use std::path::Path;
use std::time::Duration;

const PARAM_MAP_CASES: usize = 400;
const BAG_PAYLOAD_CASES: usize = 200;
const VALIDATION_CASES: usize = 250;

/// Maps where a parameter's value belongs, block or flow style.
const MAP_VALUES: [&str; 4] = ["{a: 1}", "{}", "{a: {b: 2}}", "\n      a: 1"];

/// The shipped parameter file with one parameter's value replaced by a map (`{a: 1}`, where
/// the fuzzer of issue 29 found the estimator and the calibrator silently taking it) through
/// `rpkm launch --check` of the shipped launch file: exit 2 naming the file and the key.
#[test]
fn fuzzed_parameter_maps_are_refused_with_their_key() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("launch_scripts");
    let params = std::fs::read_to_string(shipped.join("params.yaml")).expect("params.yaml");
    let launch = std::fs::read_to_string(shipped.join("rpkm.launch.yaml")).expect("launch");
    // every line that sets a parameter: `    key: value` (not a group, whose value is a map:
    // `temperatures: {}`)
    let settable: Vec<(usize, String)> = params
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("    ") && !l.trim_start().starts_with('#'))
        .filter(|(_, l)| {
            !l.split_once(':')
                .is_some_and(|(_, v)| v.trim_start().starts_with('{'))
        })
        .filter_map(|(i, l)| Some((i, l.split_once(':')?.0.trim().to_owned())))
        .collect();
    assert!(settable.len() > 30, "{settable:?}");
    let failures = family(PARAM_MAP_CASES, |case| {
        let mut rng = Rng(0x9a4b_0000 + case as u64 * 1_299_709);
        let dir = scratch(&format!("pmap{case}"));
        let (at, key) = &settable[rng.below(settable.len())];
        let mut lines: Vec<String> = params.lines().map(str::to_owned).collect();
        lines[*at] = format!("    {key}: {}", rng.pick(&MAP_VALUES));
        std::fs::write(dir.join("params.yaml"), lines.join("\n")).expect("write params");
        let file = dir.join("rpkm.launch.yaml");
        std::fs::write(&file, &launch).expect("write launch");
        let mut cmd = rpkm();
        cmd.arg("launch").arg(&file).arg("--check");
        let out = run(cmd, Duration::from_secs(30));
        let names_it =
            out.stderr.contains("params.yaml") && out.stderr.contains(&format!("/{key}:"));
        let broken = match out.code {
            Some(2) if names_it => None,
            Some(2) => Some(format!("exit 2 without naming params.yaml and {key}")),
            _ => judge(&out, &[]).or_else(|| Some(format!("{key}: a map accepted"))),
        };
        let broken = broken.map(|why| keep("param-map", case, &dir, &why, &out));
        let _ = std::fs::remove_dir_all(&dir);
        (broken, out.code == Some(2))
    });
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// One corruption of a CDR payload: bytes flipped, cut, grown, or a length field (a string's
/// or a sequence's, after the 4-byte header) set huge.
fn corrupt_payload(cdr: &mut Vec<u8>, rng: &mut Rng) {
    match rng.below(4) {
        0 => {
            for _ in 0..=rng.below(4) {
                let at = rng.below(cdr.len());
                cdr[at] ^= 1 << rng.below(8);
            }
        }
        1 => cdr.truncate(rng.below(cdr.len())),
        2 => cdr.extend((0..=rng.below(9)).map(|_| (rng.next() & 0xff) as u8)),
        _ => {
            // an aligned u32 after the header: a length in most of rpkm's messages
            let words = cdr.len().saturating_sub(4) / 4;
            if words > 0 {
                let at = 4 + 4 * rng.below(words);
                cdr[at..at + 4].copy_from_slice(&[0xff, 0xff, 0xff, 0x7f]);
            }
        }
    }
}

/// The reference calibration bag rewritten with one to three payloads corrupted (the bag's
/// records and CRCs intact): the corruption of issue 29's fuzzer, which `rpkm replay` took
/// for its own failure (exit 1). Returns whether a payload was changed.
fn write_corrupt_bag(to: &Path, rng: &mut Rng) -> bool {
    use rpkm_transport::bag::{BagReader, BagWriter, BagWriterOptions, RawTopic};
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/calibration");
    let reader = BagReader::open(&src).expect("reference bag");
    let mut writer = BagWriter::create(to, BagWriterOptions::default()).expect("bag writer");
    let handles: Vec<_> = reader
        .topics()
        .iter()
        .map(|t| {
            writer
                .add_topic_raw(RawTopic {
                    name: t.name.clone(),
                    type_name: t.type_name.clone(),
                    definition: t.definition.clone(),
                    offered_qos_yaml: t.offered_qos_profiles.clone(),
                    type_hash: t.type_hash.clone(),
                })
                .expect("topic")
        })
        .collect();
    let n = reader.message_count();
    let bad: Vec<usize> = (0..=rng.below(3)).map(|_| rng.below(n)).collect();
    let mut changed = false;
    for (i, m) in reader.messages().enumerate() {
        let m = m.expect("reference message");
        let mut data = m.data.clone();
        if bad.contains(&i) {
            corrupt_payload(&mut data, rng);
            changed |= data != m.data[..];
        }
        writer
            .write_raw(handles[m.topic_index], m.log_time, m.publish_time, &data)
            .expect("write message");
    }
    writer.finish().expect("finish bag");
    changed
}

/// Bags with corrupt payloads (records and CRCs intact) through `rpkm replay` and `rpkm bag
/// campaign`: exit 0 or 2 naming the bag, and replay's 2 names the topic and the message.
#[test]
fn fuzzed_bag_payloads_end_in_0_or_2_naming_bag_topic_and_message() {
    let dir = scratch("payloads");
    let failures = family(BAG_PAYLOAD_CASES, |case| {
        let mut rng = Rng(0xba96_0000 + case as u64 * 49_979_687);
        let bag = dir.join(format!("case{case}"));
        write_corrupt_bag(&bag, &mut rng);
        let mut cmd = rpkm();
        let replay = rng.below(2) == 0;
        if replay {
            cmd.args([
                "replay",
                "--rate",
                "max",
                "--backend",
                "ipc",
                "--ipc-prefix",
            ])
            .arg(format!("fzb{}_{case}_", std::process::id()));
        } else {
            cmd.args(["bag", "campaign", "--out"])
                .arg(dir.join(format!("c{case}.csv")));
        }
        cmd.arg(&bag);
        let out = run(cmd, Duration::from_secs(60));
        let places = [format!("case{case}")];
        let mut broken = judge(&out, &places);
        // replay publishes what decodes: a payload that does not is named by topic and
        // message (`rpkm bag campaign` judges what decodes too, and names the message by
        // its type and seq, or the rebuilt campaign's row)
        if broken.is_none() && out.code == Some(2) && replay {
            let topic = out.stderr.contains("/rpkm/");
            let message = out.stderr.contains("message ");
            if !(topic && message) {
                broken = Some("exit 2 without naming the topic and the message".to_owned());
            }
        }
        let broken = broken.map(|why| keep("payload", case, &bag, &why, &out));
        let _ = std::fs::remove_dir_all(&bag);
        let _ = std::fs::remove_file(dir.join(format!("c{case}.csv")));
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// A validation campaign's row with its measured x or y moved `by_mm`: a reading far from
/// where the machine is (5 m: outside the workspace). Returns the 1-based line changed.
fn move_a_reading(lines: &mut [String], by_mm: f64, rng: &mut Rng) -> Option<usize> {
    // t,setup,instrument,reset,q1..q4,f1..f4,follower,x,y,...: x is field 13, y 14
    let rows: Vec<usize> = (1..lines.len())
        .filter(|&i| {
            let f: Vec<&str> = lines[i].split(',').collect();
            f.len() > 14 && f[3] == "0" && !f[13].is_empty()
        })
        .collect();
    if rows.is_empty() {
        return None;
    }
    let i = rows[rng.below(rows.len())];
    let mut fields: Vec<String> = lines[i].split(',').map(str::to_owned).collect();
    let k = 13 + rng.below(2);
    let v: f64 = fields[k].parse().ok()?;
    fields[k] = format!("{}", v + by_mm);
    lines[i] = fields.join(",");
    Some(i + 1)
}

/// Validation campaigns (`rpkm calibrate C --validate V`) mutated as the calibration
/// campaigns are, and in a third of the cases with one reading moved 5 m (the fuzzer of
/// issue 29 found such a row accepted without a word): exit 0 or 2 naming the validation
/// file, and the moved reading is always refused naming its line.
#[test]
fn fuzzed_validation_campaigns_end_in_0_or_2_naming_their_file() {
    let dir = scratch("val");
    let (base, val) = (dir.join("base.csv"), dir.join("val.csv"));
    for (file, seed) in [(&base, "3"), (&val, "4")] {
        simulated_lt_campaign(file, seed);
    }
    let text = std::fs::read_to_string(&val).expect("validation campaign");
    let failures = family(VALIDATION_CASES, |case| {
        let mut rng = Rng(0x7a1d_0000 + case as u64 * 86_028_121);
        let file = dir.join(format!("val{case}.csv"));
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        let moved = if rng.below(3) == 0 {
            move_a_reading(&mut lines, 5000.0, &mut rng)
        } else {
            None
        };
        let bytes = match moved {
            Some(_) => lines.join("\n").into_bytes(),
            None => mutate_text(&lines.join("\n"), &mut rng),
        };
        std::fs::write(&file, bytes).expect("write case");
        let mut cmd = rpkm();
        cmd.arg("calibrate").arg(&base).arg("--validate").arg(&file);
        let out = run(cmd, Duration::from_secs(60));
        let name = format!("val{case}.csv");
        let mut broken = judge(&out, std::slice::from_ref(&name));
        if let (None, Some(line)) = (&broken, moved) {
            if !(out.code == Some(2) && out.stderr.contains(&format!("{name}:{line}"))) {
                broken = Some(format!("a reading 5 m off at line {line} not refused"));
            }
        }
        let broken = broken.map(|why| keep("validation", case, &file, &why, &out));
        let _ = std::fs::remove_file(&file);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

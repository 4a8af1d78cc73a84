//! Each node parameter is declared once (`rpkm_nodes::node::declare`): the shipped
//! launch_scripts/params.yaml, the descriptors of the parameter services and the defaults are
//! checked against the declarations here.

use std::path::{Path, PathBuf};

use rpkm_nodes::node::declare::{ParamBound, ParamDefault, ParamSpec};
use rpkm_nodes::node::{declarations, NodeParams, COMMON, EXECUTABLES};
use rpkm_transport::dds_params::{ParamRange, ParameterValue};

/// Keys params.yaml sets to something other than the default, on purpose (its comments say
/// so): ingest's JointState view at every 10th state, a PreloadStatus every 10th sample.
const NOT_DEFAULT: [(&str, &str); 2] = [
    ("ingest", "view_every"),
    ("preload_monitor", "status_every"),
];

fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("launch_scripts/params.yaml")
}

fn all(exec: &str) -> Vec<ParamSpec> {
    let mut specs = declarations(exec).expect("a node of the set");
    specs.extend(COMMON);
    specs
}

/// Whether `p` gives `spec` its default, read through the declaration's own typed reader (so
/// the value's type and bound are checked too).
fn is_default(spec: &ParamSpec, p: &NodeParams) -> Result<bool, String> {
    let e = |e: rpkm_nodes::node::ParamError| e.to_string();
    Ok(match spec.default {
        ParamDefault::F64(d) => spec.f64(p).map_err(e)?.to_bits() == d.to_bits(),
        ParamDefault::U64(d) => spec.u64(p).map_err(e)? == d,
        ParamDefault::Bool(d) => spec.bool(p).map_err(e)? == d,
        ParamDefault::Str(d) => spec.string(p).map_err(e)? == d,
        ParamDefault::Strs(d) => spec.strings(p).map_err(e)? == d,
        ParamDefault::F64s(d) => spec.f64s(p).map_err(e)? == d,
        ParamDefault::Group => p.group(spec.key).is_ok() || p.string_group(spec.key).is_ok(),
    })
}

/// Every key of the shipped file is one the node it addresses declares, of the declared type
/// and bound, and the declared default (but for [`NOT_DEFAULT`]); every key of the wildcard
/// section is declared by some node.
#[test]
fn the_shipped_params_yaml_holds_the_declared_keys_types_and_defaults() {
    let file = shipped();
    let mut set = 0;
    let mut wrong = Vec::new();
    for exec in EXECUTABLES {
        let p = NodeParams::load(exec, std::slice::from_ref(&file), &[]).expect("params.yaml");
        let specs = all(exec);
        let keys: Vec<&str> = specs.iter().map(|s| s.key).collect();
        p.check_declared(&keys)
            .unwrap_or_else(|e| panic!("{exec}: {e}"));
        for spec in specs.iter().filter(|s| p.has(s.key)) {
            set += 1;
            let default = is_default(spec, &p).unwrap_or_else(|e| panic!("{exec}: {e}"));
            if default == NOT_DEFAULT.contains(&(exec, spec.key)) {
                wrong.push(format!("{exec}/{}", spec.key));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "params.yaml says every key is the default unless on purpose (NOT_DEFAULT): {wrong:?}"
    );
    assert!(
        set > 40,
        "only {set} keys read: is params.yaml the shipped one?"
    );
    let text = std::fs::read_to_string(&file).expect("params.yaml");
    let doc = rpkm_nodes::node::params::parse_yaml(&text, "params.yaml").expect("yaml");
    let wildcard = doc
        .get("/**")
        .and_then(|s| s.get("ros__parameters"))
        .and_then(|m| m.as_mapping())
        .expect("a /** section");
    for key in wildcard.keys().filter_map(|k| k.as_str()) {
        assert!(
            EXECUTABLES
                .iter()
                .any(|exec| all(exec).iter().any(|s| s.key == key)),
            "/**/{key}: no node declares it"
        );
    }
}

/// No node declares a key twice (the tables of its own, the geometry's, the input's and the
/// common ones together).
#[test]
fn no_node_declares_a_key_twice() {
    for exec in EXECUTABLES {
        let specs = all(exec);
        for (i, s) in specs.iter().enumerate() {
            assert!(
                !specs[..i].iter().any(|t| t.key == s.key),
                "{exec}: {} declared twice",
                s.key
            );
        }
    }
}

/// The descriptor of every parameter: its default as the value where nothing is set, its
/// declared type, read-only unless live, the range of its bound, a description with its unit;
/// and every default lies within its own bound (set explicitly, the reader takes it).
#[test]
fn descriptors_carry_the_declared_default_range_and_unit_and_defaults_lie_in_bounds() {
    for exec in EXECUTABLES {
        let empty = NodeParams::empty(exec);
        for spec in all(exec) {
            if spec.default == ParamDefault::Group {
                continue;
            }
            let d = spec
                .decl(&empty)
                .unwrap_or_else(|e| panic!("{exec}/{}: {e}", spec.key));
            let want = match spec.default {
                ParamDefault::F64(x) => ParameterValue::Double(x),
                ParamDefault::U64(x) => ParameterValue::Integer(i64::try_from(x).expect("small")),
                ParamDefault::Bool(x) => ParameterValue::Boolean(x),
                ParamDefault::Str(x) => ParameterValue::String(x.to_owned()),
                ParamDefault::Strs(x) => {
                    ParameterValue::StringArray(x.iter().map(|s| (*s).to_owned()).collect())
                }
                ParamDefault::F64s(x) => ParameterValue::DoubleArray(x.to_vec()),
                ParamDefault::Group => unreachable!("skipped above"),
            };
            assert_eq!(d.value, want, "{exec}/{}", spec.key);
            assert_eq!(d.read_only, !spec.live, "{exec}/{}", spec.key);
            let range = match spec.bound {
                ParamBound::Within(lo, hi) => ParamRange::Float(lo, hi),
                ParamBound::Count(lo, hi) => {
                    ParamRange::Integer(i64::try_from(lo).unwrap(), i64::try_from(hi).unwrap())
                }
                ParamBound::Any | ParamBound::Positive => ParamRange::None,
            };
            assert_eq!(d.range, range, "{exec}/{}", spec.key);
            assert!(
                d.description.starts_with(spec.description) && d.description.contains(spec.unit),
                "{exec}/{}: {:?}",
                spec.key,
                d.description
            );
            // the default, set in a file, passes the node's own reader
            let text = match spec.default {
                ParamDefault::F64(x) => format!("{x:?}"),
                ParamDefault::U64(x) => x.to_string(),
                ParamDefault::Bool(x) => x.to_string(),
                ParamDefault::Str(x) => format!("{x:?}"),
                ParamDefault::Strs(x) => format!("{x:?}"),
                ParamDefault::F64s(x) => format!("{x:?}"),
                ParamDefault::Group => unreachable!("skipped above"),
            };
            let set = NodeParams::load(exec, &[], &[format!("{}={text}", spec.key)])
                .expect("an override");
            assert_eq!(
                is_default(&spec, &set),
                Ok(true),
                "{exec}/{}={text}",
                spec.key
            );
        }
    }
}

/// Defaults that are the core's: the online tracker's noise levels are the calibration's
/// stated ones, ingest's force limit is five nominal drive forces.
#[test]
fn defaults_taken_from_the_core_equal_the_core_s() {
    let calibrator = all("calibrator");
    let default_of = |key: &str| {
        calibrator
            .iter()
            .find(|s| s.key == key)
            .map(ParamSpec::default_f64)
            .expect(key)
    };
    let core = rpkm_core::online::OnlineOptions::default();
    assert_eq!(
        default_of("online_force_sigma_n").to_bits(),
        core.force_sigma_n.to_bits()
    );
    let encoder_um = rpkm_nodes::units::um_from_mm(core.encoder_sigma_mm);
    assert!(
        (default_of("online_encoder_sigma_um") - encoder_um).abs() < 1e-12,
        "{encoder_um} µm"
    );
    let force_max = all("ingest")
        .iter()
        .find(|s| s.key == "force_max_n")
        .map(ParamSpec::default_f64);
    assert_eq!(
        force_max,
        Some(5.0 * rpkm_core::elastic::NOMINAL_DRIVE_FORCE_N)
    );
}

//! Unit tests of `launch`.

use super::*;
use std::path::{Path, PathBuf};

const FILE: &str = "\
launch:
  - arg: {name: backend, default: ipc}
  - arg: {name: rate}
  - set_env: {name: ROS_DOMAIN_ID, value: \"7\"}
  - node:
      pkg: rpkm
      exec: tcp_estimator
      name: estimator_a
      param:
        - from: params.yaml
        - {name: model, value: 24}
        - {name: source, value: $(dirname)/c.csv}
      args: --backend $(var backend) --param rate_hz=$(var rate)
      respawn: \"false\"
  - node: {pkg: rpkm, exec: ingest}
  - node: {pkg: rpkm, exec: calibrator, unless: \"$(var rate)\"}
  - executable:
      cmd: rpkm record --out $(dirname)/bag --topics /rpkm/tcp_estimate
      if: \"1\"
";

#[test]
fn parses_nodes_args_and_substitutions() -> Result<(), LaunchError> {
    let d = LaunchDescription::parse(FILE, "x.launch.yaml", Path::new("/l"), &["rate:=1".into()])?;
    assert_eq!(d.env, vec![("ROS_DOMAIN_ID".into(), "7".into())]);
    let a = &d.nodes[0];
    assert_eq!(a.name, "estimator_a");
    assert_eq!(a.param_files, vec![PathBuf::from("/l/params.yaml")]);
    assert_eq!(a.params, vec!["model=24", "source=/l/c.csv"]);
    assert_eq!(a.args, ["--backend", "ipc", "--param", "rate_hz=1"]);
    assert!(!a.respawn);
    let b = &d.nodes[1];
    assert_eq!(
        (b.name.as_str(), b.respawn, b.respawn_delay),
        ("ingest", true, 0.2)
    );
    // `unless: 1` left the calibrator out; the recorder is an rpkm command.
    assert_eq!(d.nodes.len(), 3);
    let r = &d.nodes[2];
    assert_eq!(
        (r.program, r.exec.as_str(), r.name.as_str(), r.respawn),
        (LaunchProgram::Command, "record", "record", false)
    );
    assert_eq!(
        r.args,
        ["--out", "/l/bag", "--topics", "/rpkm/tcp_estimate"]
    );
    Ok(())
}

#[test]
fn unknown_keys_in_a_launch_entry_are_rejected_with_the_line() {
    refused_with(&[
        (
            "launch:\n  - node:\n      pkg: rpkm\n      exec: ingest\n      If: \"false\"\n",
            "z.yaml:5: node: unknown key \"If\" (known: pkg, exec,",
        ),
        (
            "launch:\n  - node: {pkg: rpkm, exec: ingest}\n  \
                 - executable: {cmd: rpkm record, respwan: false}\n",
            "z.yaml:3: executable: unknown key \"respwan\"",
        ),
        (
            "launch:\n  - arg: {name: a, defualt: 1}\n",
            "z.yaml:2: arg: unknown key \"defualt\"",
        ),
        (
            "launch:\n  - node: {pkg: rpkm, exec: ingest, param: [{form: p.yaml}]}\n",
            "z.yaml:2: node ingest param entry: unknown key \"form\"",
        ),
    ]);
}

#[test]
fn errors_name_the_problem() {
    let e = LaunchDescription::parse(FILE, "x.launch.yaml", Path::new("/l"), &[])
        .expect_err("rate has no default");
    assert!(e.to_string().contains("rate has no default"), "{e}");
    let e = LaunchDescription::parse(
        "launch:\n  - node: {pkg: rpkm, exec: talker}\n",
        "y.yaml",
        Path::new("."),
        &[],
    )
    .expect_err("unknown exec");
    assert!(
        e.to_string().starts_with("y.yaml:2: node exec \"talker\""),
        "{e}"
    );
    let e = LaunchDescription::parse(
        FILE,
        "x",
        Path::new("."),
        &["rate:=1".into(), "nope:=2".into()],
    )
    .expect_err("undeclared");
    assert!(e.to_string().contains("nope"), "{e}");
    for (entry, says) in [
        (
            "executable: {cmd: ros2 bag record -a}",
            "only rpkm commands",
        ),
        (
            "executable: {cmd: rpkm launch x.yaml}",
            "expected `rpkm record`",
        ),
        (
            "node: {pkg: rpkm, exec: ingest, if: maybe}",
            "node if: \"maybe\"",
        ),
        (
            "node: {pkg: rpkm, exec: ingest, respawn_delay: 1e308}",
            "node ingest: respawn_delay \"1e308\": expected seconds from 0 to 3600",
        ),
    ] {
        let e = LaunchDescription::parse(
            &format!("launch:\n  - {entry}\n"),
            "z.yaml",
            Path::new("."),
            &[],
        )
        .expect_err(entry);
        assert!(e.to_string().contains(says), "{entry}: {e}");
    }
}

#[test]
fn every_error_names_the_line_of_its_entry_or_key() {
    refused_with(&[
        (
            "# c\nlaunch:\n  - arg: {name: a, default: x}\n\n  - node:\n      pkg: rpkm\n      \
                 exec: talker\n",
            "z.yaml:7: node exec \"talker\"",
        ),
        (
            "launch:\n- node: {pkg: rpkm, exec: ingest}\n- node:\n    pkg: ros\n",
            "z.yaml:4: node pkg \"ros\"",
        ),
        (
            "launch:\n  - node:\n      pkg: rpkm\n      exec: ingest\n      respawn: maybe\n",
            "z.yaml:5: node ingest: respawn \"maybe\"",
        ),
        (
            "launch:\n  - node: {pkg: rpkm, exec: ingest}\n  - node: {pkg: rpkm, exec: ingest}\n  \
                 - executable:\n      cmd: rpkm record\n      unless: 2\n",
            "z.yaml:6: executable unless: \"2\"",
        ),
        (
            "launch:\n  - arg: {name: a}\n",
            "z.yaml:2: launch argument a has no default",
        ),
        // a flow list: the `launch:` line
        (
            "\nlaunch: [{node: {pkg: rpkm, exec: x}}]\n",
            "z.yaml:2: node exec \"x\"",
        ),
        (
            "other: 1\n",
            "z.yaml:1: expected a top-level `launch:` list",
        ),
        (
            "# two documents\nlaunch: []\n---\nlaunch: []\n",
            "z.yaml:3:1: not YAML",
        ),
    ]);
}

/// `enclave:` reaches the node as rcl's `--ros-args --enclave`.
#[test]
fn an_enclave_goes_to_the_node_as_ros_args() -> Result<(), LaunchError> {
    let d = LaunchDescription::parse(
        "launch:\n  - node:\n      pkg: rpkm\n      exec: tcp_estimator\n      \
             enclave: /cell/estimator_a\n",
        "n.yaml",
        Path::new("."),
        &[],
    )?;
    let argv: Vec<String> = d.nodes[0]
        .argv()
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        argv[argv.len() - 3..],
        ["--ros-args", "--enclave", "/cell/estimator_a"]
    );
    Ok(())
}

/// `namespace:` and `remap:` reach the node as rcl's `--ros-args -r`, last on its line;
/// a name ROS 2 would refuse is refused with its key's line, as an unusable node name is
/// (an enclave too).
#[test]
fn namespace_and_remap_go_to_the_node_as_ros_args() -> Result<(), LaunchError> {
    let entry = "launch:\n  - node:\n      pkg: rpkm\n      exec: tcp_estimator\n";
    let d = LaunchDescription::parse(
        &format!(
            "{entry}      namespace: /machine_a\n      \
                 remap: [{{from: tcp_estimate, to: /cell/estimate_a}}]\n"
        ),
        "n.yaml",
        Path::new("."),
        &[],
    )?;
    let argv: Vec<String> = d.nodes[0]
        .argv()
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        argv[argv.len() - 5..],
        [
            "--ros-args",
            "-r",
            "__ns:=/machine_a",
            "-r",
            "tcp_estimate:=/cell/estimate_a"
        ]
    );
    for (tail, says) in [
        (
            "      namespace: machine_a\n",
            "n.yaml:5: node tcp_estimator: namespace \"machine_a\": expected an absolute",
        ),
        (
            "      remap: [{from: a, to: b c}]\n",
            "n.yaml:5: node tcp_estimator: remap \"a:=b c\"",
        ),
        (
            "      name: 1st\n",
            "n.yaml:5: node name \"1st\" starts with a digit",
        ),
        (
            &format!("      name: {}\n", "a".repeat(5000)),
            "n.yaml:5: node name \"aaaa",
        ),
        (
            "      enclave: rpkm/estimator\n",
            "n.yaml:5: node tcp_estimator: enclave \"rpkm/estimator\": expected an absolute",
        ),
    ] {
        let e = LaunchDescription::parse(&format!("{entry}{tail}"), "n.yaml", Path::new("."), &[])
            .expect_err(tail);
        assert!(e.to_string().starts_with(says), "{tail}: {e}");
    }
    Ok(())
}

#[test]
fn invalid_utf8_names_line_and_byte() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("u.yaml");
    std::fs::write(&file, b"launch:\n  - arg: {name: a, default: \xc3(}\n").expect("write");
    let e = LaunchDescription::load(&file, &[]).expect_err("not UTF-8");
    // "launch:\n" is 8 bytes, "  - arg: {name: a, default: " 28
    assert_eq!(
        e.to_string(),
        format!(
            "{}:2: invalid UTF-8 at byte 36, expected UTF-8 text",
            file.display()
        )
    );
}

/// Each launch text is refused, its error starting with what it says (`z.yaml:LINE: ...`).
fn refused_with(cases: &[(&str, &str)]) {
    for (text, says) in cases {
        let e = LaunchDescription::parse(text, "z.yaml", Path::new("."), &[]).expect_err(text);
        assert!(e.to_string().starts_with(says), "{text}: {e}");
    }
}

/// ROS 2's `let` and `$(equals A B)`, nested in a substitution: the shipped launch file's
/// backend rule (both for a ros2_control cell's source, else ipc, a given backend stands).
#[test]
fn let_and_equals_choose_the_backend_by_the_source() -> Result<(), LaunchError> {
    let file = "launch:\n  - arg: {name: source, default: dds}\n  \
                - arg: {name: backend, default: auto}\n  \
                - let: {name: backend, value: both, if: \"$(equals $(var backend)/$(var source) auto/joint_states)\"}\n  \
                - let: {name: backend, value: ipc, if: \"$(equals $(var backend) auto)\"}\n  \
                - node: {pkg: rpkm, exec: ingest, args: --backend $(var backend)}\n";
    for (given, backend) in [
        (vec!["source:=joint_states"], "both"),
        (vec![], "ipc"),
        (vec!["source:=c.csv"], "ipc"),
        (vec!["source:=joint_states", "backend:=dds"], "dds"),
        (vec!["source:=dds", "backend:=both"], "both"),
    ] {
        let given: Vec<String> = given.into_iter().map(str::to_owned).collect();
        let d = LaunchDescription::parse(file, "b.yaml", Path::new("/l"), &given)?;
        assert_eq!(d.nodes[0].args, ["--backend", backend], "{given:?}");
    }
    let ctx = |text: &str| {
        LaunchDescription::parse(
            &format!("launch:\n  - node: {{pkg: rpkm, exec: ingest, args: \"{text}\"}}\n"),
            "e.yaml",
            Path::new("."),
            &[],
        )
        .map(|d| d.nodes[0].args.join(" "))
    };
    assert_eq!(
        ctx("$(equals 1 true) $(equals 2.0 2) $(equals a b)")?,
        "true true false"
    );
    let e = ctx("$(equals a)").expect_err("one argument");
    assert!(
        e.to_string().contains("unknown substitution $(equals a)"),
        "{e}"
    );
    Ok(())
}

/// `{from: $(var params_file)}`: empty (the argument's default) passes no file; a file
/// given on the command line is used as given (relative to the working directory), one
/// written in the launch file relative to its folder; files keep their order.
#[test]
fn a_parameter_file_of_the_cell_layers_after_the_shipped_one() -> Result<(), LaunchError> {
    let file = "launch:\n  - arg: {name: params_file, default: \"\"}\n  \
                - node:\n      pkg: rpkm\n      exec: ingest\n      param:\n        \
                - from: params.yaml\n        - from: $(var params_file)\n";
    let d = LaunchDescription::parse(file, "p.yaml", Path::new("/l"), &[])?;
    assert_eq!(d.nodes[0].param_files, [PathBuf::from("/l/params.yaml")]);
    let d = LaunchDescription::parse(
        file,
        "p.yaml",
        Path::new("/l"),
        &["params_file:=cell.yaml".into()],
    )?;
    assert_eq!(
        d.nodes[0].param_files,
        [PathBuf::from("/l/params.yaml"), PathBuf::from("cell.yaml")]
    );
    let argv: Vec<String> = d.nodes[0]
        .argv()
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        argv[..4],
        [
            "ingest",
            "--name=ingest",
            "--params=/l/params.yaml",
            "--params=cell.yaml"
        ]
    );
    Ok(())
}

/// A child that is handed a start-up pipe, running `script` under `sh`: how its start ended
/// for the launch.
fn start_of(script: &str) -> ready::NodeStart {
    tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .enable_io()
        .build()
        .expect("runtime")
        .block_on(async {
            let pipe = ready::ReadyPipe::new().expect("pipe");
            let mut cmd = tokio::process::Command::new("sh");
            cmd.args(["-c", script]);
            pipe.pass_to(&mut cmd);
            let mut child = cmd.spawn().expect("sh");
            let start = pipe.wait().await;
            child.wait().await.expect("wait");
            start
        })
}

#[test]
fn a_child_that_writes_to_its_start_up_pipe_has_started_one_that_exits_has_not() {
    // the descriptor is open in the child (not closed on exec) under the number it is told
    let said = start_of("sleep 0.2; printf x > /proc/self/fd/$RPKM_READY_FD; sleep 0.5");
    assert!(
        matches!(said, ready::NodeStart::Said(t) if t >= std::time::Duration::from_millis(200)),
        "the byte after 0.2 s"
    );
    assert!(matches!(start_of("sleep 0.2"), ready::NodeStart::Ended));
}

//! msgs/ is a ROS 2 interface package: tests/python/build_interface_package.py builds it as
//! colcon would, with the rosidl generators Debian ships (rosidl-core, ament-cmake) and small
//! stand-ins for rosidl_default_generators/runtime and builtin_interfaces, then compiles a
//! package that finds rpkm_msgs and uses every message and the action's types from C++. A
//! package.xml without the interface-package declarations, or a CMakeLists.txt that leaves
//! out a .msg, must fail.
//!
//! Without the tooling the test is skipped with the reason, except under
//! `RPKM_REQUIRE_PYTHON` (set by .ci/run, which installs it), where it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Exit code of the script when cmake, a compiler or the rosidl tooling is missing.
const TOOLING_MISSING: i32 = 3;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The script's output; `None` when there is no python3 at all.
fn build(msgs: &Path, workspace: &Path) -> Option<Output> {
    Command::new("python3")
        .arg(repo().join("tests/python/build_interface_package.py"))
        .arg(msgs)
        .arg(workspace)
        .output()
        .ok()
}

/// Skips (returns `None`) where the tooling is missing, except under `RPKM_REQUIRE_PYTHON`.
fn tooling_present(out: Option<Output>) -> Option<Output> {
    let reason = match &out {
        None => "python3 not found".to_owned(),
        Some(o) if o.status.code() == Some(TOOLING_MISSING) => text(o).trim().to_owned(),
        Some(_) => return out,
    };
    assert!(
        std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
        "CI: the rosidl tooling is required (.ci/run installs it): {reason}"
    );
    eprintln!("SKIPPED: {reason}");
    None
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// A copy of msgs/ (the ROS package's files only) with `edit` applied to `file`.
fn broken_copy(dir: &Path, file: &str, edit: impl Fn(&str) -> String) -> PathBuf {
    let copy = dir.join(format!("broken-{}", file.replace('.', "-")));
    let msgs = repo().join("msgs");
    for folder in ["msg", "srv", "action"] {
        std::fs::create_dir_all(copy.join(folder)).expect("dir");
        for entry in std::fs::read_dir(msgs.join(folder)).expect("msg/, srv/, action/") {
            let path = entry.expect("entry").path();
            std::fs::copy(
                &path,
                copy.join(folder).join(path.file_name().expect("name")),
            )
            .expect("copy");
        }
    }
    for name in ["package.xml", "CMakeLists.txt"] {
        let original = std::fs::read_to_string(msgs.join(name)).expect("read");
        let changed = if name == file {
            edit(&original)
        } else {
            original.clone()
        };
        assert!(
            name != file || changed != original,
            "the edit of {file} changes nothing"
        );
        std::fs::write(copy.join(name), changed).expect("write");
    }
    copy
}

#[test]
fn msgs_builds_as_a_ros2_interface_package_with_rosidl() {
    let dir = std::env::temp_dir().join(format!("rpkm-rosidl-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let workspace = dir.join("ws");
    let Some(out) = tooling_present(build(&repo().join("msgs"), &workspace)) else {
        return;
    };
    assert!(out.status.success(), "{}", text(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json report");
    let mut expected: Vec<String> = std::fs::read_dir(repo().join("msgs/msg"))
        .expect("msg/")
        .map(|e| format!("msg/{}", e.expect("entry").file_name().to_string_lossy()))
        .collect();
    // rosidl turns a service into its request and response messages
    for e in std::fs::read_dir(repo().join("msgs/srv")).expect("srv/") {
        let name = e.expect("entry").file_name().to_string_lossy().into_owned();
        let stem = name.trim_end_matches(".srv");
        expected.push(format!("srv/{stem}_Request.msg"));
        expected.push(format!("srv/{stem}_Response.msg"));
    }
    // an action as itself
    for e in std::fs::read_dir(repo().join("msgs/action")).expect("action/") {
        let name = e.expect("entry").file_name().to_string_lossy().into_owned();
        expected.push(format!("action/{name}"));
    }
    expected.sort();
    assert!(expected.contains(&"action/Calibrate.action".to_owned()));
    assert_eq!(report["interfaces"], serde_json::json!(expected));
    assert_eq!(
        report["depends"],
        serde_json::json!(["action_msgs", "builtin_interfaces"])
    );

    // a message left out of rosidl_generate_interfaces (one no other interface uses: a left
    // out Parameters.msg fails earlier, when the action's result is compiled)
    let unlisted = broken_copy(&dir, "CMakeLists.txt", |t| {
        t.replace("  \"msg/PreloadStatus.msg\"\n", "")
    });
    let out = build(&unlisted, &workspace).expect("python3 runs");
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        text(&out).contains("msg/, srv/ and action/ hold"),
        "{}",
        text(&out)
    );

    // not in the rosidl_interface_packages group (colcon would not order it before users)
    let ungrouped = broken_copy(&dir, "package.xml", |t| {
        t.replace(
            "<member_of_group>rosidl_interface_packages</member_of_group>",
            "",
        )
    });
    let out = build(&ungrouped, &workspace).expect("python3 runs");
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        text(&out).contains("not a member of rosidl_interface_packages"),
        "{}",
        text(&out)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

//! A plant's PostgreSQL credentials where the plant keeps them, against a real server (the
//! test run's, history_support) with a role that must give its password (SCRAM): the URL
//! names no password; `PGPASSWORD` records, a password file (`PGPASSFILE`, mode 0600)
//! records; a wrong password exits 2 naming the user and host, from `rpkm calibrate` and
//! from the calibrator node; a password file others may read is ignored, and the refusal
//! says so. A campaign recorded again is said to be the same campaign (by `rpkm calibrate`
//! and `rpkm history`).

use crate::history_support::{postgres::server, scenario, MACHINE};
use crate::node_support::TempDir;
use std::os::unix::fs::PermissionsExt;
use std::process::{Command, Output};

const ROLE: &str = "plant_cell";
const PASSWORD: &str = "s3cret:pw";

/// A command with none of the caller's libpq settings, and `env` over them.
fn clean(mut c: Command, env: &[(&str, &str)]) -> Command {
    for k in [
        "PGPASSWORD",
        "PGPASSFILE",
        "PGHOST",
        "PGPORT",
        "PGUSER",
        "PGDATABASE",
        "PGSERVICE",
        "PGSERVICEFILE",
    ] {
        c.env_remove(k);
    }
    // never the user's own ~/.pgpass
    c.env("PGPASSFILE", "/nonexistent/pgpass");
    c.envs(env.iter().copied());
    c
}

/// `rpkm calibrate` of campaign `k` into `url` with `env`, at the time of campaign `at`.
fn calibrate_at(url: &str, k: usize, at: usize, env: &[(&str, &str)]) -> Output {
    let s = scenario();
    let mut c = Command::new(env!("CARGO_BIN_EXE_rpkm"));
    c.arg("calibrate").arg(s.campaign(k)).args([
        "--history",
        url,
        "--machine",
        MACHINE,
        "--at",
        &s.at(at),
    ]);
    clean(c, env).output().expect("run rpkm calibrate")
}

fn calibrate(url: &str, k: usize, env: &[(&str, &str)]) -> Output {
    calibrate_at(url, k, k, env)
}

fn said(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A password file of `text` with `mode`.
fn pgpass(dir: &TempDir, name: &str, text: &str, mode: u32) -> String {
    let path = dir.path(name);
    std::fs::write(&path, text).expect("pgpass");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).expect("chmod");
    path.to_string_lossy().into_owned()
}

#[test]
fn the_password_comes_from_the_environment_or_the_password_file_and_a_wrong_one_exits_2() {
    let Some(server) = server() else { return };
    server.database("credentials");
    server.require_password(ROLE, PASSWORD);
    let url = format!("postgres://{ROLE}@127.0.0.1:{}/credentials", server.port);
    let dir = TempDir::new("pgcred");

    let o = calibrate(&url, 0, &[("PGPASSWORD", PASSWORD)]);
    assert!(o.status.success(), "PGPASSWORD: {}", said(&o));
    assert!(said(&o).contains("recorded as calibration"), "{}", said(&o));

    // the password file: a wildcard port, the password's colon escaped
    let file = pgpass(
        &dir,
        "pgpass",
        &format!("# plant\n127.0.0.1:*:credentials:{ROLE}:s3cret\\:pw\n"),
        0o600,
    );
    let o = calibrate(&url, 1, &[("PGPASSFILE", &file)]);
    assert!(o.status.success(), "PGPASSFILE: {}", said(&o));
    assert!(said(&o).contains("recorded as calibration"), "{}", said(&o));

    let o = calibrate(&url, 2, &[("PGPASSWORD", "wrong")]);
    assert_eq!(o.status.code(), Some(2), "{}", said(&o));
    let text = said(&o);
    assert!(
        text.contains(&format!("{ROLE}@127.0.0.1:{}", server.port))
            && text.contains("password authentication failed"),
        "{text}"
    );

    // readable by others: ignored as libpq ignores it, and said
    let open = pgpass(
        &dir,
        "pgpass-open",
        &format!("*:*:*:{ROLE}:{PASSWORD}\n"),
        0o644,
    );
    let o = calibrate(&url, 2, &[("PGPASSFILE", &open)]);
    assert_eq!(o.status.code(), Some(2), "{}", said(&o));
    assert!(
        said(&o).contains("password missing") && said(&o).contains("mode 0644"),
        "{}",
        said(&o)
    );

    // the first campaign again, a month later: recorded, and said to be the same campaign,
    // here and in the history
    let o = calibrate_at(&url, 0, 3, &[("PGPASSWORD", PASSWORD)]);
    assert!(
        said(&o).contains("the same campaign as calibration 1"),
        "{}",
        said(&o)
    );
    let mut c = Command::new(env!("CARGO_BIN_EXE_rpkm"));
    c.args(["history", &url, "--machine", MACHINE]);
    let o = clean(c, &[("PGPASSWORD", PASSWORD)])
        .output()
        .expect("rpkm history");
    assert!(
        said(&o).contains("calibration 3 is the same campaign as calibration 1"),
        "{}",
        said(&o)
    );

    // the node: a wrong password is a configuration error, not a crash to restart
    let mut c = Command::new(env!("CARGO_BIN_EXE_rpkm"));
    c.args(["node", "calibrator", "--backend", "ipc", "--param"])
        .arg(format!("history={url}"))
        .env("RPKM_IPC_PREFIX", crate::node_support::unique("pgcred"));
    let o = clean(c, &[("PGPASSWORD", "wrong")])
        .output()
        .expect("run the node");
    assert_eq!(o.status.code(), Some(2), "{}", said(&o));
    assert!(
        said(&o).contains(&format!("{ROLE}@127.0.0.1")),
        "{}",
        said(&o)
    );
}

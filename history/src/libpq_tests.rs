//! libpq's completion of a URL: the precedence URL > service > environment > password file,
//! the password file's wildcards and escapes, and a readable password file ignored.

use super::{pgpass_match, resolve, Target};
use std::collections::HashMap;
use std::io::Write;

fn env_of(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
    let map: HashMap<String, String> = pairs
        .iter()
        .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
        .collect();
    move |k| map.get(k).cloned()
}

fn target() -> Target {
    Target {
        host: "plant-db".to_owned(),
        port: "5432".to_owned(),
        database: "history".to_owned(),
        user: "cell".to_owned(),
    }
}

#[test]
fn a_password_file_line_matches_with_wildcards_and_escapes() {
    let t = target();
    assert_eq!(
        pgpass_match("plant-db:5432:history:cell:s3cret", &t).as_deref(),
        Some("s3cret")
    );
    assert_eq!(
        pgpass_match("*:*:*:cell:a\\:b\\\\c:d", &t).as_deref(),
        Some("a:b\\c:d"),
        "escaped colon and backslash; the rest of the line is the password"
    );
    assert_eq!(pgpass_match("other:*:*:cell:x", &t), None);
    assert_eq!(pgpass_match("*:5433:*:cell:x", &t), None);
    assert_eq!(pgpass_match("*:*:*:operator:x", &t), None);
    assert_eq!(pgpass_match("# *:*:*:*:x", &t), None);
    assert_eq!(pgpass_match("*:*:*:cell", &t), None, "four fields");
    // an escaped star is a literal star, not a wildcard
    assert_eq!(pgpass_match("\\*:*:*:cell:x", &t), None);
}

fn password(r: &super::Resolved) -> Option<String> {
    r.config
        .get_password()
        .map(|p| String::from_utf8_lossy(p).into_owned())
}

fn pgpass(dir: &std::path::Path, text: &str, mode: u32) -> String {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join("pgpass");
    let mut f = std::fs::File::create(&path).expect("create");
    f.write_all(text.as_bytes()).expect("write");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).expect("chmod");
    path.to_string_lossy().into_owned()
}

#[test]
fn the_url_wins_over_the_environment_which_wins_over_the_password_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = pgpass(dir.path(), "*:*:*:*:from-file\n", 0o600);
    let env = env_of(&[
        ("PGHOST", "plant-db"),
        ("PGPORT", "6543"),
        ("PGUSER", "cell"),
        ("PGDATABASE", "history"),
        ("PGPASSWORD", "from-env"),
        ("PGPASSFILE", &file),
    ]);
    let r = resolve("postgres://op:from-url@db-2:7000/h2", &env).expect("resolves");
    assert_eq!(r.shown, "postgres://op@db-2:7000/h2");
    assert_eq!(password(&r).as_deref(), Some("from-url"));
    let r = resolve("postgres://", &env).expect("resolves");
    assert_eq!(r.shown, "postgres://cell@plant-db:6543/history");
    assert_eq!(password(&r).as_deref(), Some("from-env"));
    // a host of the URL without a port: the environment's port, as libpq takes it
    let r = resolve("postgres://db-3,db-4:7001/h3", &env).expect("resolves");
    assert_eq!(r.shown, "postgres://cell@db-3:6543/h3");
    assert_eq!(r.config.get_ports(), [6543, 7001]);
    let without = env_of(&[
        ("PGHOST", "plant-db"),
        ("PGUSER", "cell"),
        ("PGPASSFILE", &file),
    ]);
    let r = resolve("postgres:///history", &without).expect("resolves");
    assert_eq!(password(&r).as_deref(), Some("from-file"));
    assert!(r.notes.is_empty());
}

#[test]
fn a_password_file_others_may_read_is_ignored_with_a_warning() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = pgpass(dir.path(), "*:*:*:*:from-file\n", 0o644);
    let env = env_of(&[("PGUSER", "cell"), ("PGPASSFILE", &file)]);
    let r = resolve("postgres://plant-db/history", &env).expect("resolves");
    assert_eq!(password(&r), None);
    assert_eq!(r.notes.len(), 1);
    assert!(r.notes[0].contains("mode 0644"), "{:?}", r.notes);
}

#[test]
fn a_service_fills_what_the_url_leaves_before_the_environment() {
    let dir = tempfile::tempdir().expect("tempdir");
    let services = dir.path().join("services.conf");
    std::fs::write(
        &services,
        "# plant\n[other]\nhost=nowhere\n\n[history]\nhost=plant-db\nport=6000\n\
         dbname=cells\nuser=cell\nsslmode=prefer\n",
    )
    .expect("write");
    let env = env_of(&[
        ("PGSERVICE", "history"),
        ("PGSERVICEFILE", &services.to_string_lossy()),
        ("PGHOST", "env-host"),
        ("PGPORT", "7000"),
    ]);
    let r = resolve("postgres:///override", &env).expect("resolves");
    assert_eq!(r.shown, "postgres://cell@plant-db:6000/override");
    let env = env_of(&[
        ("PGSERVICE", "missing"),
        ("PGSERVICEFILE", &services.to_string_lossy()),
    ]);
    let e = resolve("postgres://", &env).err().expect("no such service");
    assert_eq!(e.fault(), crate::StoreFault::Configuration);
}

#[test]
fn a_bad_url_or_port_is_a_configuration_error() {
    let env = env_of(&[]);
    for url in [
        "postgres://h:notaport/db",
        "postgres://h/db?sslmode=nonsense",
    ] {
        let Err(e) = resolve(url, &env) else {
            panic!("{url} accepted")
        };
        assert_eq!(e.fault(), crate::StoreFault::Configuration, "{e}");
    }
    let e = resolve("postgres://h/db", &env_of(&[("PGPORT", "x")]))
        .err()
        .expect("refused");
    assert!(e.to_string().contains("PGPORT"), "{e}");
}

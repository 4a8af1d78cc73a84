//! The connection settings of a `postgres://` URL completed as libpq completes them, so that
//! a plant's credentials stay where the plant keeps them (the `postgres` client reads none of
//! these itself): what the URL leaves out comes from the service file of `PGSERVICE`, then
//! the environment (`PGHOST`, `PGPORT`, `PGDATABASE`, `PGUSER`, `PGPASSWORD`,
//! `PGCONNECT_TIMEOUT`), then the defaults (the Unix socket `/var/run/postgresql`, port
//! 5432, the OS user, a database named as the user); a password still missing is looked up
//! in the password file (`PGPASSFILE`, else `~/.pgpass`), which, as libpq does, is ignored
//! with a warning when its group or others may read it.

use crate::error::StoreError;
use crate::pg::without_password;
use postgres::config::Host;
use postgres::Config;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

/// libpq's default socket directory on Debian, and its default port.
const DEFAULT_SOCKET_DIR: &str = "/var/run/postgresql";
const DEFAULT_PORT: u16 = 5432;
/// How long a connection attempt may take where neither the URL nor `PGCONNECT_TIMEOUT`
/// says (libpq waits without end; a writer that retries must not).
const DEFAULT_CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// The environment a URL is completed from: a variable's value by name.
pub type Env<'a> = &'a dyn Fn(&str) -> Option<String>;

/// The process's environment.
pub fn process_env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

/// A URL completed: the client's settings, where they lead (no password), and what the
/// completion noticed on the way (a password file ignored).
pub struct Resolved {
    pub config: Config,
    /// `postgres://user@host:port/database`.
    pub shown: String,
    pub notes: Vec<String>,
}

/// A configuration error of `location`.
fn config_error(location: &str, what: String) -> StoreError {
    StoreError::Config {
        location: location.to_owned(),
        what,
    }
}

/// Completes `url` from `env` as libpq would.
pub fn resolve(url: &str, env: Env) -> Result<Resolved, StoreError> {
    let given = without_password(url);
    let parse = |u: &str| {
        Config::from_str(u).map_err(|e| config_error(&given, format!("not a PostgreSQL URL: {e}")))
    };
    let mut config = parse(url)?;
    let mut port = fill(&mut config, env, &given)?;
    // the client gives a host of the URL without a port 5432: a port of the service or
    // the environment goes in its place
    if url_names_every_port(url) {
        port = None;
    }
    if let Some(p) = port {
        if config.get_ports().is_empty() {
            config.port(p);
        } else {
            config = parse(&with_port(url, p))?;
            fill(&mut config, env, &given)?;
        }
    }
    if config.get_hosts().is_empty() {
        config.host(DEFAULT_SOCKET_DIR);
    }
    if config.get_ports().is_empty() {
        config.port(DEFAULT_PORT);
    }
    if config.get_user().is_none() {
        let user = whoami::username()
            .map_err(|e| config_error(&given, format!("no user given and no OS user: {e}")))?;
        config.user(&user);
    }
    if config.get_connect_timeout().is_none() {
        config.connect_timeout(DEFAULT_CONNECT_TIMEOUT);
    }
    let shown = shown(&config);
    let mut notes = Vec::new();
    if config.get_password().is_none() {
        if let Some(file) = password_file(env) {
            match password_from_file(&file, &Target::of(&config)) {
                Ok(Some(p)) => {
                    config.password(p);
                }
                Ok(None) => {}
                Err(note) => notes.push(note),
            }
        }
    }
    Ok(Resolved {
        config,
        shown,
        notes,
    })
}

/// Fills what the URL left out from the service, then the environment; the port they
/// give, if any (set here only where the URL has no host).
fn fill(c: &mut Config, env: Env, given: &str) -> Result<Option<u16>, StoreError> {
    let mut port = None;
    if let Some(service) = env("PGSERVICE") {
        port = apply_service(c, &service, env, given)?;
    }
    apply_env(c, env, given)?;
    if port.is_none() {
        if let Some(p) = env("PGPORT") {
            port = Some(parse_port(&p, "PGPORT", given)?);
        }
    }
    Ok(port)
}

/// A URL in three: up to its hosts (`postgres://user@`), the hosts, and the rest.
fn authority(url: &str) -> (&str, &str, &str) {
    let Some((scheme, rest)) = url.split_once("://") else {
        return ("", "", url);
    };
    let end = rest.find(['/', '?']).unwrap_or(rest.len());
    let (auth, tail) = rest.split_at(end);
    let at = auth.rfind('@').map_or(0, |i| i + 1);
    let (user, hosts) = auth.split_at(at);
    (&url[..scheme.len() + 3 + user.len()], hosts, tail)
}

/// Whether a host of the URL names its port (`host:5433`, `[::1]:5433`).
fn names_port(host: &str) -> bool {
    match host.strip_prefix('[') {
        Some(h) => h.contains("]:"),
        None => host.contains(':'),
    }
}

fn url_names_every_port(url: &str) -> bool {
    let (_, hosts, _) = authority(url);
    hosts.split(',').all(names_port)
}

/// The URL with `port` on each of its hosts that has none.
fn with_port(url: &str, port: u16) -> String {
    let (head, hosts, tail) = authority(url);
    let hosts: Vec<String> = hosts
        .split(',')
        .map(|h| {
            if names_port(h) {
                h.to_owned()
            } else {
                format!("{h}:{port}")
            }
        })
        .collect();
    format!("{head}{}{tail}", hosts.join(","))
}

/// The first host as libpq names it in messages and matches it in the password file: a
/// socket directory as its path, the default one as `localhost`.
fn host_name(h: &Host) -> String {
    match h {
        Host::Tcp(name) => name.clone(),
        #[cfg(unix)]
        Host::Unix(path) => path.to_string_lossy().into_owned(),
    }
}

/// `postgres://user@host:port/database` of completed settings.
fn shown(c: &Config) -> String {
    let user = c.get_user().unwrap_or_default();
    let host = c.get_hosts().first().map(host_name).unwrap_or_default();
    let port = c.get_ports().first().copied().unwrap_or(DEFAULT_PORT);
    let db = c.get_dbname().unwrap_or(user);
    format!("postgres://{user}@{host}:{port}/{db}")
}

/// What the password file is matched against.
#[derive(Debug)]
struct Target {
    host: String,
    port: String,
    database: String,
    user: String,
}

impl Target {
    fn of(c: &Config) -> Target {
        let user = c.get_user().unwrap_or_default().to_owned();
        let host = c
            .get_hosts()
            .first()
            .map_or_else(|| "localhost".to_owned(), host_name);
        Target {
            // libpq: the default socket directory matches as `localhost`
            host: if host == DEFAULT_SOCKET_DIR {
                "localhost".to_owned()
            } else {
                host
            },
            port: c
                .get_ports()
                .first()
                .copied()
                .unwrap_or(DEFAULT_PORT)
                .to_string(),
            database: c.get_dbname().unwrap_or(&user).to_owned(),
            user,
        }
    }
}

/// Fills what the URL left out from the environment.
fn apply_env(c: &mut Config, env: Env, given: &str) -> Result<(), StoreError> {
    if c.get_hosts().is_empty() {
        if let Some(h) = env("PGHOST") {
            c.host(&h);
        }
    }
    if c.get_dbname().is_none() {
        if let Some(d) = env("PGDATABASE") {
            c.dbname(&d);
        }
    }
    if c.get_user().is_none() {
        if let Some(u) = env("PGUSER") {
            c.user(&u);
        }
    }
    if c.get_password().is_none() {
        if let Some(p) = env("PGPASSWORD") {
            c.password(p);
        }
    }
    if c.get_connect_timeout().is_none() {
        if let Some(t) = env("PGCONNECT_TIMEOUT") {
            c.connect_timeout(parse_timeout(&t, "PGCONNECT_TIMEOUT", given)?);
        }
    }
    Ok(())
}

fn parse_port(p: &str, what: &str, given: &str) -> Result<u16, StoreError> {
    p.trim()
        .parse()
        .map_err(|_| config_error(given, format!("{what}: not a port: {p:?}")))
}

/// libpq's connect_timeout: whole seconds, 0 or none meaning "wait without end" (here: the
/// default bound), at least 2 s.
fn parse_timeout(t: &str, what: &str, given: &str) -> Result<Duration, StoreError> {
    let s: u64 = t
        .trim()
        .parse()
        .map_err(|_| config_error(given, format!("{what}: not whole seconds: {t:?}")))?;
    Ok(match s {
        0 => DEFAULT_CONNECT_TIMEOUT,
        s => Duration::from_secs(s.max(2)),
    })
}

/// The password file: `PGPASSFILE`, else `~/.pgpass`.
fn password_file(env: Env) -> Option<PathBuf> {
    env("PGPASSFILE")
        .map(PathBuf::from)
        .or_else(|| env("HOME").map(|h| Path::new(&h).join(".pgpass")))
}

/// The password of the first line of `file` that matches `t`; `Err` (a warning) where the
/// file is not a plain file or group or others may read it, as libpq warns and ignores it.
fn password_from_file(file: &Path, t: &Target) -> Result<Option<String>, String> {
    let Ok(meta) = std::fs::metadata(file) else {
        return Ok(None);
    };
    if !meta.is_file() {
        return Err(format!(
            "password file {} is not a plain file: ignored",
            file.display()
        ));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(format!(
                "password file {} has group or world access (mode {mode:04o}): ignored; \
                 permissions should be u=rw (0600) or less",
                file.display()
            ));
        }
    }
    let text = std::fs::read_to_string(file)
        .map_err(|e| format!("password file {}: {e}: ignored", file.display()))?;
    Ok(text.lines().find_map(|line| pgpass_match(line, t)))
}

/// A line of a password file, `host:port:database:user:password`, each of the first four
/// `*` (anything) or the value, `\:` and `\\` standing for `:` and `\`; its password where
/// it matches `t`. Comments (`#`) and short lines match nothing.
fn pgpass_match(line: &str, t: &Target) -> Option<String> {
    if line.starts_with('#') {
        return None;
    }
    let fields = split_escaped(line);
    let [host, port, database, user, password] = fields.as_slice() else {
        return None;
    };
    let fits = |f: &Field, v: &str| f.star || f.text == v;
    let all = fits(host, &t.host)
        && fits(port, &t.port)
        && fits(database, &t.database)
        && fits(user, &t.user);
    all.then(|| password.text.clone())
}

/// A field of a password file line: its text unescaped, and whether it was a bare `*`.
struct Field {
    text: String,
    star: bool,
}

/// The first four fields split at unescaped colons, the rest (colons and all) the fifth.
fn split_escaped(line: &str) -> Vec<Field> {
    let mut fields = Vec::new();
    let (mut text, mut raw) = (String::new(), String::new());
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '\\' => {
                raw.push(c);
                if let Some(n) = chars.next() {
                    text.push(n);
                    raw.push(n);
                }
            }
            ':' if fields.len() < 4 => {
                fields.push(Field {
                    star: raw == "*",
                    text: std::mem::take(&mut text),
                });
                raw.clear();
            }
            c => {
                text.push(c);
                raw.push(c);
            }
        }
    }
    fields.push(Field {
        star: raw == "*",
        text,
    });
    fields
}

/// The service file of libpq: `PGSERVICEFILE`, else `~/.pg_service.conf`, then
/// `$PGSYSCONFDIR/pg_service.conf`; the first that defines `service` fills what the URL
/// left out (before the environment, as in libpq).
fn apply_service(
    c: &mut Config,
    service: &str,
    env: Env,
    given: &str,
) -> Result<Option<u16>, StoreError> {
    let files = [
        env("PGSERVICEFILE")
            .map(PathBuf::from)
            .or_else(|| env("HOME").map(|h| Path::new(&h).join(".pg_service.conf"))),
        env("PGSYSCONFDIR").map(|d| Path::new(&d).join("pg_service.conf")),
    ];
    for file in files.into_iter().flatten() {
        let Ok(text) = std::fs::read_to_string(&file) else {
            continue;
        };
        if let Some(keys) = service_section(&text, service) {
            let mut port = None;
            for (line, key, value) in keys {
                let at = |what: String| {
                    config_error(given, format!("{}:{line}: {what}", file.display()))
                };
                if key == "port" {
                    port = Some(value.parse().map_err(|_| at(format!("port: {value:?}")))?);
                } else {
                    apply_key(c, &key, &value).map_err(at)?;
                }
            }
            return Ok(port);
        }
    }
    Err(config_error(
        given,
        format!("PGSERVICE {service:?}: no such service in the service files"),
    ))
}

/// The `key=value` lines (with their line numbers) of section `[service]`, if there is one.
fn service_section(text: &str, service: &str) -> Option<Vec<(usize, String, String)>> {
    let mut inside = false;
    let mut found = false;
    let mut keys = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            inside = name == service;
            found |= inside;
        } else if inside {
            let (k, v) = line.split_once('=').unwrap_or((line, ""));
            keys.push((n + 1, k.trim().to_owned(), v.trim().to_owned()));
        }
    }
    found.then_some(keys)
}

/// One service-file setting, where the URL did not set it.
fn apply_key(c: &mut Config, key: &str, value: &str) -> Result<(), String> {
    match key {
        "host" if c.get_hosts().is_empty() => {
            c.host(value);
        }
        "dbname" if c.get_dbname().is_none() => {
            c.dbname(value);
        }
        "user" if c.get_user().is_none() => {
            c.user(value);
        }
        "password" if c.get_password().is_none() => {
            c.password(value);
        }
        "connect_timeout" if c.get_connect_timeout().is_none() => {
            c.connect_timeout(
                parse_timeout(value, "connect_timeout", "").map_err(|e| e.to_string())?,
            );
        }
        // no TLS here: a service that asks for it is refused, one that allows plain is not
        "sslmode" if !["disable", "allow", "prefer"].contains(&value) => {
            return Err(format!("sslmode={value}: rpkm connects without TLS"));
        }
        "host" | "port" | "dbname" | "user" | "password" | "connect_timeout" | "sslmode" => {}
        other => return Err(format!("{other}: a setting rpkm does not know")),
    }
    Ok(())
}

#[cfg(test)]
#[path = "libpq_tests.rs"]
mod tests;

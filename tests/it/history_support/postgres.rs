//! A PostgreSQL server of the test run's own (Debian's package: /usr/lib/postgresql/N/bin),
//! started once for every test that needs one: a data directory under the target's tmp, a
//! free port on 127.0.0.1, trust authentication for the user `rpkm`. Root (CI) runs it as
//! the `postgres` user, which initdb and the server require. The server is the child of a
//! thread that lives as long as the test process and gets SIGINT (fast shutdown) when the
//! process ends, however it ends (`setpriv --pdeathsig`).
//!
//! Where the package is missing the tests that need it skip with a word, except under
//! `RPKM_REQUIRE_POSTGRES=1` (.ci/run), where that is a failure.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// A running server.
pub struct Server {
    pub port: u16,
    data: PathBuf,
}

/// The server's binaries: the newest Debian installs.
fn bin_dir() -> Option<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path().join("bin")))
        .filter(|d| d.join("postgres").exists() && d.join("initdb").exists())
        .collect();
    dirs.sort();
    dirs.pop()
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions and touches no memory.
    unsafe { libc::geteuid() == 0 }
}

/// `cmd` as the `postgres` user when root (initdb and the server refuse root).
fn as_server_user(bin: &Path) -> Command {
    let mut c = Command::new("setpriv");
    if is_root() {
        c.args(["--reuid=postgres", "--regid=postgres", "--init-groups"]);
    }
    c.arg("--pdeathsig=INT").arg("--").arg(bin);
    c
}

/// A free port on 127.0.0.1 (the OS's choice of one, released for the server).
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    l.local_addr().expect("addr").port()
}

/// A data directory `tag` of the test run made by initdb (trust for the user `rpkm`); the
/// server's binaries. None (skip) without the package.
fn init(tag: &str) -> Option<(PathBuf, PathBuf)> {
    let Some(bin) = bin_dir() else {
        assert!(
            std::env::var_os("RPKM_REQUIRE_POSTGRES").is_none(),
            "RPKM_REQUIRE_POSTGRES is set but /usr/lib/postgresql/*/bin has no server"
        );
        eprintln!("SKIPPED: no PostgreSQL server (apt-get install postgresql)");
        return None;
    };
    let data = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&data);
    std::fs::create_dir_all(&data).expect("data dir");
    if is_root() {
        let status = Command::new("chown")
            .args(["-R", "postgres:postgres"])
            .arg(&data)
            .status()
            .expect("chown");
        assert!(status.success(), "chown {}", data.display());
    }
    let init = as_server_user(&bin.join("initdb"))
        .args(["-A", "trust", "-U", "rpkm", "--no-sync", "-D"])
        .arg(&data)
        .output()
        .expect("initdb");
    assert!(
        init.status.success(),
        "initdb: {}",
        String::from_utf8_lossy(&init.stderr)
    );
    Some((bin, data))
}

/// The server of `data` on `port` (its socket in `data`), as the caller's child.
fn spawn(bin: &Path, data: &Path, port: u16) -> std::process::Child {
    as_server_user(&bin.join("postgres"))
        .arg("-D")
        .arg(data)
        .args(["-p", &port.to_string(), "-k"])
        .arg(data)
        .args(["-c", "listen_addresses=127.0.0.1", "-c", "fsync=off"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start postgres")
}

fn start() -> Option<Server> {
    let (bin, data) = init("pg")?;
    let port = free_port();
    let sock = data.clone();
    // the server's parent: a thread that never ends before the process does
    std::thread::spawn(move || {
        let mut child = spawn(&bin, &sock, port);
        let _ = child.wait();
        loop {
            std::thread::park();
        }
    });
    wait_ready(port);
    Some(Server { port, data })
}

/// Waits until the server answers (at most 60 s).
fn wait_ready(port: u16) {
    let url = format!("postgres://rpkm@127.0.0.1:{port}/postgres");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        match postgres::Client::connect(&url, postgres::NoTls) {
            Ok(_) => return,
            Err(e) => assert!(Instant::now() < deadline, "PostgreSQL on {port}: {e}"),
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The test run's server, started at the first call; None (skip) without the package.
pub fn server() -> Option<&'static Server> {
    static SERVER: OnceLock<Option<Server>> = OnceLock::new();
    SERVER.get_or_init(start).as_ref()
}

impl Server {
    /// A new empty database `name`; its URL.
    pub fn database(&self, name: &str) -> String {
        let admin = format!("postgres://rpkm@127.0.0.1:{}/postgres", self.port);
        let mut c = postgres::Client::connect(&admin, postgres::NoTls).expect("connect");
        // each its own statement: neither runs inside a transaction block
        c.batch_execute(&format!("DROP DATABASE IF EXISTS {name}"))
            .expect("drop database");
        c.batch_execute(&format!("CREATE DATABASE {name}"))
            .expect("create database");
        format!("postgres://rpkm@127.0.0.1:{}/{name}", self.port)
    }
}

impl Server {
    /// A role `role` that must give `password` (SCRAM) from 127.0.0.1, the other roles
    /// still trusted: a rule before the others in pg_hba.conf, and the server reloaded.
    pub fn require_password(&self, role: &str, password: &str) {
        let hba = self.data.join("pg_hba.conf");
        let text = std::fs::read_to_string(&hba).expect("pg_hba.conf");
        let rule = format!("host all {role} 127.0.0.1/32 scram-sha-256\n");
        if !text.contains(&rule) {
            std::fs::write(&hba, format!("{rule}{text}")).expect("pg_hba.conf");
        }
        let admin = format!("postgres://rpkm@127.0.0.1:{}/postgres", self.port);
        let mut c = postgres::Client::connect(&admin, postgres::NoTls).expect("connect");
        c.batch_execute(&format!(
            "DROP ROLE IF EXISTS {role}; CREATE ROLE {role} LOGIN SUPERUSER PASSWORD '{password}'"
        ))
        .expect("role");
        c.batch_execute("SELECT pg_reload_conf()").expect("reload");
        // the reload is asynchronous: wait until the rule holds
        let url = format!("postgres://{role}@127.0.0.1:{}/postgres", self.port);
        let deadline = Instant::now() + Duration::from_secs(10);
        while postgres::Client::connect(&url, postgres::NoTls).is_ok() {
            assert!(Instant::now() < deadline, "pg_hba.conf not reloaded");
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// A server of one test's own, which the test stops and starts again (its data kept), as a
/// plant's database restarts under a running cell; stopped when dropped.
pub struct OwnServer {
    pub port: u16,
    bin: PathBuf,
    data: PathBuf,
    child: Option<std::process::Child>,
}

impl OwnServer {
    /// A new server `tag`, started; None (skip) without the package.
    pub fn new(tag: &str) -> Option<OwnServer> {
        let (bin, data) = init(tag)?;
        let mut s = OwnServer {
            port: free_port(),
            bin,
            data,
            child: None,
        };
        s.start();
        Some(s)
    }

    /// Starts it (again) and waits until it answers.
    pub fn start(&mut self) {
        self.child = Some(spawn(&self.bin, &self.data, self.port));
        wait_ready(self.port);
    }

    /// Stops it as `pg_ctl stop -m fast` does (SIGINT: the sessions are ended), and waits.
    pub fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let pid = i32::try_from(c.id()).expect("pid");
            // SAFETY: kill has no memory preconditions; the pid is our child's.
            unsafe {
                libc::kill(pid, libc::SIGINT);
            }
            let _ = c.wait();
        }
    }

    /// A new empty database `name`; its URL.
    pub fn database(&self, name: &str) -> String {
        Server {
            port: self.port,
            data: self.data.clone(),
        }
        .database(name)
    }
}

impl Drop for OwnServer {
    fn drop(&mut self) {
        self.stop();
    }
}

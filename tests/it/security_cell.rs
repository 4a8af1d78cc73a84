//! The cell secured with SROS2 as issue 31 asks: the shipped launch file on the demo
//! campaign over DDS, every program in its own enclave of a keystore made by
//! `rpkm security`, `ROS_SECURITY_STRATEGY=Enforce`, the estimates recorded by `rpkm record`
//! (enclave `/rpkm/record`). Meanwhile, on the same domain:
//!
//! - a Cyclone DDS participant without credentials (tests/python/unauthenticated_peer.py)
//!   matches no rpkm endpoint, receives no estimate and no parameter-service answer (and, as
//!   the control, does match and get answers from a node started without security);
//! - a Cyclone DDS participant with DDS Security (Debian's libddsc 0.10.2 and its standard
//!   plugins, tests/cpp/secure_peer.c) in an enclave of the same keystore: where it receives
//!   estimates they are exactly those the recorder recorded; where it receives none, the
//!   reason must be the known disagreement (docs/nodes.md, "Security"): RustDDS refuses
//!   Cyclone's handshake request, whose key agreement name `ECDH+prime256v1-CEUM` Cyclone
//!   sends with its terminating NUL;
//! - tcpdump on the loopback interface: no estimate's x and y (IEEE 754, little-endian, side
//!   by side as CDR carries them) appear in the captured traffic, while the same search
//!   finds each in the recorded bag.

use crate::bag_support::decode_all;
use crate::node_support::{python, rpkm, unique, Proc, TempDir};
use crate::security_support::{env, keystore, required};

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use rpkm_msgs::TcpEstimate;

const DOMAIN: &str = "92";
/// Debian's Cyclone DDS keeps its security plugins here (package libddsc0debian).
const PLUGINS: &str = "/usr/lib/x86_64-linux-gnu/libddsc0debian";

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The secure peer compiled against Debian's Cyclone DDS (idlc for its type), once.
fn secure_peer() -> Option<PathBuf> {
    static PEER: OnceLock<Option<PathBuf>> = OnceLock::new();
    PEER.get_or_init(|| {
        let have = Path::new("/usr/include/dds/dds.h").is_file()
            && Path::new(PLUGINS).join("libdds_security_auth.so").is_file()
            && Command::new("idlc").arg("-v").output().is_ok();
        if !required(
            have,
            "Cyclone DDS with security (cyclonedds-dev, cyclonedds-tools)",
        ) {
            return None;
        }
        let dir = std::env::temp_dir().join(unique("secure_peer"));
        std::fs::create_dir_all(&dir).expect("dir");
        let idl = repo().join("tests/cpp/tcp_estimate.idl");
        let ok = Command::new("idlc")
            .args(["-l", "c"])
            .arg(&idl)
            .current_dir(&dir)
            .status()
            .expect("idlc runs");
        assert!(ok.success(), "idlc {}", idl.display());
        let out = dir.join("secure_peer");
        let ok = Command::new("gcc")
            .args(["-O1", "-I"])
            .arg(&dir)
            .arg("-o")
            .arg(&out)
            .arg(repo().join("tests/cpp/secure_peer.c"))
            .arg(dir.join("tcp_estimate.c"))
            .arg("-lddsc")
            .status()
            .expect("gcc runs");
        assert!(ok.success(), "secure_peer.c does not compile");
        Some(out)
    })
    .clone()
}

/// Cyclone's configuration: loopback discovery as the other peers (tests/python/loopback.py),
/// its warnings traced into `trace`, and DDS Security with the enclave `dir`'s files and
/// Debian's plugins.
fn cyclone_security_xml(dir: &Path, trace: &Path) -> String {
    let file = |f: &str| format!("file:{}", dir.join(f).display());
    let lib = |name: &str, init: &str, fin: &str| {
        format!(
            r#"<Library path="{PLUGINS}/libdds_security_{name}.so" initFunction="{init}" finalizeFunction="{fin}"/>"#
        )
    };
    format!(
        r#"<CycloneDDS><Domain id="any">
  <General><Interfaces><NetworkInterface name="lo"/></Interfaces>
    <AllowMulticast>false</AllowMulticast></General>
  <Discovery><Peers><Peer address="127.0.0.1"/></Peers>
    <ParticipantIndex>auto</ParticipantIndex>
    <MaxAutoParticipantIndex>60</MaxAutoParticipantIndex></Discovery>
  <Tracing><Verbosity>warning</Verbosity><OutputFile>{}</OutputFile></Tracing>
  <Security>
    <Authentication>{}
      <IdentityCA>{}</IdentityCA>
      <IdentityCertificate>{}</IdentityCertificate>
      <PrivateKey>{}</PrivateKey>
    </Authentication>
    <AccessControl>{}
      <PermissionsCA>{}</PermissionsCA>
      <Governance>{}</Governance>
      <Permissions>{}</Permissions>
    </AccessControl>
    <Cryptographic>{}</Cryptographic>
  </Security>
</Domain></CycloneDDS>"#,
        trace.display(),
        lib("auth", "init_authentication", "finalize_authentication"),
        file("identity_ca.cert.pem"),
        file("cert.pem"),
        file("key.pem"),
        lib("ac", "init_access_control", "finalize_access_control"),
        file("permissions_ca.cert.pem"),
        file("governance.p7s"),
        file("permissions.p7s"),
        lib("crypto", "init_crypto", "finalize_crypto"),
    )
}

/// tcpdump on `lo` (UDP: RTPS), packet-buffered into `file`; stopped with SIGINT.
struct Capture {
    child: Child,
    file: PathBuf,
}

impl Capture {
    fn start(file: PathBuf) -> Option<Self> {
        if !required(
            Command::new("tcpdump").arg("--version").output().is_ok(),
            "tcpdump",
        ) {
            return None;
        }
        let child = Command::new("tcpdump")
            .args(["-i", "lo", "-U", "-s", "0", "-w"])
            .arg(&file)
            .arg("udp")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start tcpdump");
        // tcpdump has opened the interface once it has written the file's header
        let up = Instant::now() + Duration::from_secs(10);
        while std::fs::metadata(&file).map_or(0, |m| m.len()) == 0 && Instant::now() < up {
            std::thread::sleep(Duration::from_millis(20));
        }
        Some(Self { child, file })
    }

    fn stop(mut self) -> Vec<u8> {
        let _ = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
        std::fs::read(&self.file).expect("capture file")
    }
}

/// Lines of a child's stdout, in a channel.
fn lines(child: &mut Child) -> Receiver<String> {
    let out = child.stdout.take().expect("piped stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    rx
}

/// How many times `needle` occurs in `hay`.
fn occurrences(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len()).filter(|w| *w == needle).count()
}

/// The unauthenticated peer on the domain, asking `node`, for `seconds` or until `until`
/// exists.
fn unauthenticated(py: &Path, seconds: u32, node: &str, until: &Path) -> Child {
    Command::new(py)
        .arg(repo().join("tests/python/unauthenticated_peer.py"))
        .args(["--domain", DOMAIN, "--seconds", &seconds.to_string()])
        .args(["--node", node])
        .arg("--until")
        .arg(until)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start unauthenticated_peer.py")
}

fn verdict(child: Child) -> serde_json::Value {
    let out = child.wait_with_output().expect("peer ends");
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().unwrap_or(""))
        .unwrap_or_else(|e| panic!("unauthenticated_peer.py: {e}: {text}"))
}

/// `rpkm launch` of the shipped launch file, its stderr lines in a channel. Its parameter
/// file is the shipped one as a secured cell sets it (docs/nodes.md, "Security"): ingest
/// streams the campaign 10 s after its start, when the six participants have
/// authenticated each other (after the default 1 s the demo's first samples went to no one).
fn launch(keys: &Path, dir: &Path, bag_dir: &Path) -> (Proc, Receiver<String>) {
    let shipped = repo().join("launch_scripts");
    for file in ["rpkm.launch.yaml", "params.yaml"] {
        std::fs::copy(shipped.join(file), dir.join(file)).expect("copy the launch files");
    }
    let params = std::fs::read_to_string(dir.join("params.yaml")).expect("params.yaml");
    let secured = params.replacen("    start_delay_s: 1.0 ", "    start_delay_s: 10.0", 1);
    assert_ne!(
        secured, params,
        "params.yaml sets start_delay_s: 1.0 no more"
    );
    std::fs::write(dir.join("params.yaml"), secured).expect("params.yaml");
    let source = format!(
        "source:={}",
        repo().join("bags/demo/campaign.csv").display()
    );
    let mut child = Command::new(rpkm())
        .arg("launch")
        .arg(dir.join("rpkm.launch.yaml"))
        .args([source.as_str(), "backend:=dds", "record:=true"])
        .arg(format!("bag_dir:={}", bag_dir.display()))
        .envs(env(keys, "Enforce"))
        .env("ROS_DOMAIN_ID", DOMAIN)
        // the DDS library's errors too: the secure peer's handshake is judged by them
        .env("RPKM_LOG", "info")
        .env("RPKM_IPC_PREFIX", unique("seccell"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start rpkm launch");
    let err = child.stderr.take().expect("piped");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            eprintln!("{line}");
            let _ = tx.send(line);
        }
    });
    (Proc(child), rx)
}

/// Reads lines into `seen` until one contains `needle`.
fn wait_for(rx: &Receiver<String>, seen: &mut Vec<String>, needle: &str, timeout: Duration) {
    let deadline = Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(l) => {
                let found = l.contains(needle);
                seen.push(l);
                if found {
                    return;
                }
            }
            Err(e) => panic!("no line with {needle:?} within {timeout:?}: {e}"),
        }
    }
}

/// What RustDDS says when it refuses Cyclone DDS 0.10's handshake request.
const KAGREE_REFUSED: &str =
    r#"Unexpected c_kagree_algo in handshake request: b"ECDH+prime256v1-CEUM\0""#;

/// The one bag folder `rpkm record` wrote into `dir`.
fn the_bag(dir: &Path) -> PathBuf {
    let bags: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("bag dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.join("metadata.yaml").is_file())
        .collect();
    assert_eq!(bags.len(), 1, "bags in {}: {bags:?}", dir.display());
    bags[0].clone()
}

/// The secure Cyclone DDS peer, started with an enclave of the cell's keystore (None where
/// Debian's Cyclone is not here), and its output lines.
fn start_secure_peer(tmp: &TempDir, keys: &Path, poses: usize) -> Option<(Proc, Receiver<String>)> {
    secure_peer().map(|bin| {
        let xml = tmp.path("cyclone.xml");
        std::fs::write(
            &xml,
            cyclone_security_xml(
                &keys.join("enclaves/rpkm/secure_peer"),
                &tmp.path("cyclone.trace"),
            ),
        )
        .expect("cyclone.xml");
        let mut child = Command::new(bin)
            .args([DOMAIN, &poses.to_string(), "120"])
            .env("CYCLONEDDS_URI", format!("file://{}", xml.display()))
            .stdout(Stdio::piped())
            .spawn()
            .expect("start secure_peer");
        let rx = lines(&mut child);
        (Proc(child), rx)
    })
}

/// The bag `rpkm record` wrote in `bag_dir` and its estimates, checked: one per drive state,
/// each once, and a calibration recorded.
fn recorded(bag_dir: &Path, poses: usize) -> (PathBuf, Vec<TcpEstimate>) {
    let bag = the_bag(bag_dir);
    let estimates: Vec<TcpEstimate> = decode_all(&bag, "/rpkm/tcp_estimate");
    // One estimate per drive state, each once. The drive states are best-effort (as a
    // controller's stream): on a loaded machine a few may be lost on the way to the
    // estimator (all 194 arrived in each of five runs here), never duplicated.
    let mut seqs: Vec<u64> = estimates.iter().map(|e| e.seq).collect();
    seqs.sort_unstable();
    seqs.dedup();
    assert_eq!(seqs.len(), estimates.len(), "an estimate recorded twice");
    assert!(
        seqs.iter()
            .all(|s| (1..=u64::try_from(poses).expect("count")).contains(s))
            && seqs.len() * 10 >= poses * 9,
        "{} estimates of {poses} drive states recorded over secured DDS: {seqs:?}",
        seqs.len()
    );
    let parameters: Vec<rpkm_msgs::Parameters> = decode_all(&bag, "/rpkm/parameters");
    assert!(!parameters.is_empty(), "no calibration recorded");
    (bag, estimates)
}

/// The unauthenticated outsider, stopped: it saw no rpkm endpoint, no sample, no answer.
fn outsider_saw_nothing(outsider: Child, stop: &Path) {
    std::fs::write(stop, b"").expect("stop file");
    let seen = verdict(outsider);
    eprintln!("the outsider, during the run: {seen}");
    assert_eq!(seen["estimate_writers"], 0, "{seen}");
    assert_eq!(seen["parameter_endpoints"], 0, "{seen}");
    assert_eq!(seen["samples"], 0, "{seen}");
    assert_eq!(seen["answers"], 0, "{seen}");
    assert!(seen["requests"].as_u64().unwrap_or(0) >= 10, "{seen}");
}

/// What the secure peer received: the recorded estimates, or nothing for the known reason
/// (RustDDS and Cyclone 0.10 disagree on the handshake; docs/nodes.md, "Security").
fn secure_peer_got(
    (peer, rx): (Proc, Receiver<String>),
    estimates: &[TcpEstimate],
    said: &[String],
    trace: &Path,
) {
    // the cell is done: what the peer has, it has
    drop(peer);
    let mut got = Vec::new();
    for line in rx.iter().take_while(|l| !l.starts_with("DONE")) {
        let f: Vec<&str> = line.split(' ').collect();
        let parse = |s: &str| s.parse::<f64>().expect("number");
        got.push((f[0].parse::<u64>().expect("seq"), parse(f[1]), parse(f[2])));
    }
    let recorded: Vec<(u64, f64, f64)> = estimates.iter().map(|e| (e.seq, e.x, e.y)).collect();
    if got.is_empty() {
        let refused = said.iter().filter(|l| l.contains(KAGREE_REFUSED)).count();
        assert!(
            refused > 0,
            "the secure Cyclone peer received no estimate, and RustDDS did not say it \
             refused its handshake ({KAGREE_REFUSED}): a new disagreement"
        );
        // and Cyclone drops RustDDS's handshake messages (builtin participant stateless
        // message writer 0xc3010200), fragmented, as malformed
        let trace = std::fs::read_to_string(trace).unwrap_or_default();
        let dropped = trace
            .lines()
            .filter(|l| {
                l.contains("malformed packet received from vendor 1.18")
                    && l.contains("DATA_FRAG")
                    && l.contains("wid 0xc3010200")
            })
            .count();
        assert!(dropped > 0, "Cyclone's trace: {trace}");
        eprintln!(
            "KNOWN: the secure Cyclone DDS peer received no estimate: RustDDS refused its \
             handshake request {refused} times ({KAGREE_REFUSED}), Cyclone dropped {dropped} \
             of RustDDS's handshake messages as malformed DATA_FRAG"
        );
    } else {
        assert_eq!(got, recorded, "the secure Cyclone peer's estimates");
    }
}

/// The loopback capture holds RTPS traffic and none of the recorded estimates in clear.
fn nothing_in_clear(capture: Capture, bag: &Path, estimates: &[TcpEstimate]) {
    let pcap = capture.stop();
    let rtps = occurrences(&pcap, b"RTPS");
    assert!(rtps > 100, "the capture holds {rtps} RTPS messages");
    eprintln!("capture: {} bytes, {rtps} RTPS messages", pcap.len());
    let mcap = std::fs::read(
        std::fs::read_dir(bag)
            .expect("bag")
            .map(|e| e.expect("entry").path())
            .find(|p| p.extension().is_some_and(|x| x == "mcap"))
            .expect("mcap file"),
    )
    .expect("read mcap");
    // x and y follow each other in the CDR of a TcpEstimate: 16 bytes, unique to the
    // estimate (x alone is 0.0 at the campaign's centre: eight zero bytes, anywhere)
    let mut in_clear = Vec::new();
    for e in estimates {
        let mut bytes = e.x.to_le_bytes().to_vec();
        bytes.extend(e.y.to_le_bytes());
        assert!(
            occurrences(&mcap, &bytes) > 0,
            "the search misses seq {} in the bag",
            e.seq
        );
        if occurrences(&pcap, &bytes) > 0 {
            in_clear.push((e.seq, e.x, e.y));
        }
    }
    assert!(
        in_clear.is_empty(),
        "estimates in clear on the wire: {in_clear:?}"
    );
}

#[test]
fn the_secured_cell_runs_the_demo_and_shows_nothing_to_an_outsider() {
    let Some(py) = python() else { return };
    let tmp = TempDir::new("sec_cell");
    let keys = keystore(&tmp.0, &[("/rpkm/secure_peer", "monitor")]);
    // the campaign's rows: one drive state, so one estimate, each
    let poses = std::fs::read_to_string(repo().join("bags/demo/campaign.csv"))
        .expect("campaign")
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("t,") && !l.trim().is_empty())
        .count();
    let capture = Capture::start(tmp.path("lo.pcap"));
    let outsider_stop = tmp.path("outsider.stop");
    let outsider = unauthenticated(&py, 300, "/rpkm/tcp_estimator", &outsider_stop);
    let secure = start_secure_peer(&tmp, &keys, poses);
    let bag_dir = tmp.path("bags");
    std::fs::create_dir_all(&bag_dir).expect("bag dir");
    let (mut cell, log) = launch(&keys, &tmp.0, &bag_dir);
    let mut said = Vec::new();
    wait_for(
        &log,
        &mut said,
        "[calibrator] calibration ",
        Duration::from_secs(180),
    );
    // the last estimates reach the recorder; then Ctrl-C closes its bag
    std::thread::sleep(Duration::from_secs(2));
    let _ = Command::new("kill")
        .args(["-INT", &cell.0.id().to_string()])
        .status();
    let _ = cell.0.wait();
    said.extend(log.try_iter());

    let (bag, estimates) = recorded(&bag_dir, poses);

    outsider_saw_nothing(outsider, &outsider_stop);

    if let Some(secure) = secure {
        secure_peer_got(secure, &estimates, &said, &tmp.path("cyclone.trace"));
    }

    if let Some(capture) = capture {
        nothing_in_clear(capture, &bag, &estimates);
    }

    // The control: the same outsider against a node without security does match and get
    // its answers, so the zeros above are the security's doing.
    let node = Proc(
        Command::new(rpkm())
            .args([
                "node",
                "tcp_estimator",
                "--backend",
                "dds",
                "--name",
                "open_estimator",
            ])
            .env("ROS_DOMAIN_ID", DOMAIN)
            .env("RPKM_IPC_PREFIX", unique("seccell_open"))
            .env_remove("ROS_SECURITY_ENABLE")
            .stderr(Stdio::null())
            .spawn()
            .expect("start tcp_estimator"),
    );
    let seen = verdict(unauthenticated(
        &py,
        8,
        "/rpkm/open_estimator",
        &tmp.path("never"),
    ));
    drop(node);
    assert!(
        seen["parameter_endpoints"].as_u64().unwrap_or(0) >= 2,
        "{seen}"
    );
    assert!(seen["answers"].as_u64().unwrap_or(0) >= 1, "{seen}");
}

//! Samples larger than a datagram reach independent peers: Parameters of 1.3 kB to 81 kB,
//! published on /rpkm/parameters (reliable, transient local) through rpkm's DDS transport as
//! the calibrator publishes its calibration, are read by Eclipse Cyclone DDS
//! (tests/python/large_sample_peer.py) and eProsima Fast DDS
//! (tests/cpp/fastdds_parameters_peer.cpp, types from fastddsgen), every value as sent, bit
//! for bit.
//!
//! RustDDS sends a sample as 256-byte fragments when it exceeds the budget of the reader's
//! path (`rpkm_transport::dds_wire::unfragmented_limit`: the interface's MTU less 128 bytes).
//! Both peers use the machine's own network interface where it has one (Cyclone named to it,
//! Fast DDS by default), as a cell's peer on another host does: there every sample goes as
//! fragments (this machine's eth0 has an MTU of 1400: 1272 bytes whole). The 81 kB one goes
//! as fragments on any path, loopback included.
//!
//! Needs the venv, Fast DDS (libfastrtps-dev, fastddsgen) and g++; without them SKIPPED,
//! under RPKM_REQUIRE_PYTHON=1 (CI) a failure.

use crate::node_support;
use crate::security_support::required;

use std::fmt::Write as _;
use std::hash::{Hash, Hasher};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::sync::OnceLock;
use std::time::Duration;

use node_support::{python, unique, Proc};
use ros2_client::dds::rustdds::{self, policy, DomainParticipant, QosPolicyBuilder, TopicKind};
use rpkm_msgs::Parameters;
use rpkm_transport::{topic, Backend, Transport, TransportConfig};

const DOMAIN: u16 = 83;
const REPLY_DOMAIN: u16 = 84;
/// A reply topic as rmw names a service's (`rr/<service>Reply`).
const REPLY_TOPIC: &str = "rr/rpkm/calibrator/calibrate/_action/get_resultReply";
/// Entries of each sample's lists: 1276 bytes (whole on 1500-byte Ethernet), 2516 (the size
/// of a Calibrate result), 8916 and 80916 (above loopback's budget).
const SIZES: [usize; 4] = [29, 60, 200, 1700];
const TIMEOUT: Duration = Duration::from_secs(30);

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A Parameters whose lists have `n` entries each.
fn parameters(n: usize) -> Parameters {
    let k = |i: usize| i as f64;
    Parameters {
        model: 29,
        names: (0..n).map(|i| format!("p{i}")).collect(),
        values: (0..n).map(|i| 0.5 + k(i) * 1e-3).collect(),
        sigmas: (0..n).map(|i| 1e-6 * (k(i) + 1.0) / 3.0).collect(),
        active_effects: vec!["thermal".into(), "preload_elastic".into()],
        effect_parameter_names: (0..n).map(|i| format!("e{i}")).collect(),
        effect_parameter_values: (0..n).map(|i| -k(i) / 7.0).collect(),
        measurement_count: u32::try_from(n).expect("a small count"),
        cal_rms: 1.25e-5,
        val_rms: f64::NAN,
        max_abs_residual: 4.5e-5 + k(n),
        condition_number: 1.0e3 / 3.0,
    }
}

/// The line both peers print for a sample (float64s as their IEEE 754 bits).
fn line(p: &Parameters) -> String {
    fn words<S: AsRef<str>>(items: &[S]) -> String {
        if items.is_empty() {
            return "-".into();
        }
        items
            .iter()
            .map(AsRef::as_ref)
            .collect::<Vec<_>>()
            .join(",")
    }
    fn bits(v: f64) -> String {
        format!("{:016x}", v.to_bits())
    }
    fn numbers(v: &[f64]) -> String {
        words(&v.iter().map(|x| bits(*x)).collect::<Vec<_>>())
    }
    format!(
        "S {} {} {} {} {} {} {} {} {} {} {} {}",
        p.model,
        p.measurement_count,
        words(&p.names),
        numbers(&p.values),
        numbers(&p.sigmas),
        words(&p.active_effects),
        words(&p.effect_parameter_names),
        numbers(&p.effect_parameter_values),
        bits(p.cal_rms),
        bits(p.val_rms),
        bits(p.max_abs_residual),
        bits(p.condition_number),
    )
}

/// The machine's first network interface other than loopback that is up, if any: where a
/// peer on another host would be reached.
fn network_interface() -> Option<String> {
    let mut names: Vec<String> = std::fs::read_dir("/sys/class/net")
        .ok()?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n != "lo")
        .filter(|n| {
            std::fs::read_to_string(format!("/sys/class/net/{n}/operstate"))
                .is_ok_and(|s| s.trim() == "up")
        })
        .collect();
    names.sort();
    names.into_iter().next()
}

/// Cyclone DDS on `interface` only, discovery by multicast there: it announces that
/// interface's address, as a peer on another host would. (Cyclone ignores a participant whose
/// announcements reach it only on an interface it does not use: RustDDS's unicast ones go to
/// 127.0.0.1, its multicast ones go out on the network interface.)
fn cyclone_config(interface: &str) -> String {
    format!(
        "<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface \
         name=\"{interface}\"/></Interfaces></General><Discovery><ParticipantIndex>auto\
         </ParticipantIndex><MaxAutoParticipantIndex>60</MaxAutoParticipantIndex></Discovery>\
         </Domain></CycloneDDS>"
    )
}

/// Cyclone DDS (the peer `cmd` starts) on the machine's network interface, where it has one.
pub(crate) fn on_network_interface(cmd: &mut Command) {
    match network_interface() {
        Some(interface) => {
            eprintln!("Cyclone DDS on {interface}");
            cmd.env("CYCLONEDDS_URI", cyclone_config(&interface));
        }
        None => eprintln!("no network interface but lo: only samples above 64 kB are fragmented"),
    }
}

/// The Fast DDS reader compiled against Debian's Fast DDS, once per test run, kept in
/// target/tmp under the hash of its sources.
fn fastdds_parameters_peer() -> Option<PathBuf> {
    static PEER: OnceLock<Option<PathBuf>> = OnceLock::new();
    PEER.get_or_init(|| {
        let have = Path::new("/usr/include/fastdds/dds/domain/DomainParticipant.hpp").is_file()
            && Command::new("fastddsgen").arg("-version").output().is_ok()
            && Command::new("g++").arg("--version").output().is_ok();
        if !required(have, "Fast DDS (libfastrtps-dev, fastddsgen) and g++") {
            return None;
        }
        let sources = [
            "tests/cpp/fastdds_parameters_peer.cpp",
            "tests/cpp/fastdds_parameters.idl",
        ];
        let mut hash = std::collections::hash_map::DefaultHasher::new();
        for s in sources {
            std::fs::read(repo().join(s)).expect(s).hash(&mut hash);
        }
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("fastdds_parameters_peer-{:016x}", hash.finish()));
        let bin = dir.join("fastdds_parameters_peer");
        if bin.is_file() {
            return Some(bin);
        }
        let building = dir.with_extension(unique("building"));
        std::fs::create_dir_all(&building).expect("build dir");
        std::fs::copy(
            repo().join(sources[1]),
            building.join("fastdds_parameters.idl"),
        )
        .expect("idl");
        let ok = Command::new("fastddsgen")
            .args(["-replace", "fastdds_parameters.idl"])
            .current_dir(&building)
            .stdout(Stdio::null())
            .status()
            .expect("fastddsgen runs");
        assert!(ok.success(), "fastddsgen fastdds_parameters.idl");
        let ok = Command::new("g++")
            .args(["-O1", "-std=c++17", "-I"])
            .arg(&building)
            .arg("-o")
            .arg(building.join("fastdds_parameters_peer"))
            .arg(repo().join(sources[0]))
            .arg(building.join("fastdds_parameters.cxx"))
            .arg(building.join("fastdds_parametersPubSubTypes.cxx"))
            .args(["-lfastrtps", "-lfastcdr"])
            .status()
            .expect("g++ runs");
        assert!(ok.success(), "fastdds_parameters_peer.cpp does not compile");
        // a finished build only, under its final name (a concurrent run may have won)
        if std::fs::rename(&building, &dir).is_err() {
            let _ = std::fs::remove_dir_all(&building);
        }
        Some(bin)
    })
    .clone()
}

/// A peer's process and the lines it prints, read on a thread of their own.
struct Peer {
    name: &'static str,
    _proc: Proc,
    lines: mpsc::Receiver<String>,
}

impl Peer {
    fn start(name: &'static str, mut cmd: Command) -> Self {
        let mut child = cmd
            .stdout(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("start {name}: {e}"));
        let out = child.stdout.take().expect("stdout");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(l).is_err() {
                    break;
                }
            }
        });
        let peer = Self {
            name,
            _proc: Proc(child),
            lines,
        };
        assert_eq!(peer.next(), "READY", "{name} did not start");
        peer
    }

    /// The next line, or a failure naming the peer after the timeout.
    fn next(&self) -> String {
        self.lines
            .recv_timeout(TIMEOUT)
            .unwrap_or_else(|_| panic!("{}: nothing within {TIMEOUT:?}", self.name))
    }

    /// The next sample's line (past the Cyclone peer's MATCHED).
    fn sample(&self) -> String {
        let l = self.next();
        if l == "MATCHED" {
            self.next()
        } else {
            l
        }
    }
}

#[test]
fn parameters_of_several_kilobytes_reach_cyclone_and_fast_dds() {
    let Some(py) = python() else { return };
    let Some(fastdds) = fastdds_parameters_peer() else {
        return;
    };
    let mut cyclone = Command::new(py);
    cyclone
        .arg(repo().join("tests/python/large_sample_peer.py"))
        .args([
            "--domain",
            &DOMAIN.to_string(),
            "--topic",
            "rt/rpkm/parameters",
        ])
        .args(["--count", &SIZES.len().to_string(), "--timeout", "60"]);
    on_network_interface(&mut cyclone);
    let mut fast = Command::new(fastdds);
    fast.args([&DOMAIN.to_string(), "rt/rpkm/parameters", "parameters"])
        .args([SIZES.len().to_string(), "60".into()]);
    let peers = [
        Peer::start("cyclone", cyclone),
        Peer::start("fastdds", fast),
    ];

    let t = Transport::new(
        &TransportConfig::new(unique("frag"))
            .backend(Backend::Dds)
            .dds_domain(DOMAIN),
    )
    .expect("transport");
    let publisher = t.publisher(&topic::PARAMETERS).expect("publisher");
    for n in SIZES {
        let sent = parameters(n);
        let bytes = rpkm_msgs::to_cdr(&sent).expect("cdr").len();
        eprintln!("Parameters of {n} entries: {bytes} bytes serialized");
        publisher.publish(&sent).expect("publish");
        // One at a time: the topic keeps its last sample only (keep last 1), and a reader
        // that matches late gets that one.
        for peer in &peers {
            assert_eq!(
                peer.sample(),
                line(&sent),
                "{} received the {bytes}-byte Parameters otherwise than sent",
                peer.name
            );
        }
    }
    let sizes: Vec<usize> = SIZES
        .iter()
        .map(|n| rpkm_msgs::to_cdr(&parameters(*n)).expect("cdr").len())
        .collect();
    // What the sizes stand for: one below a 1500-byte path's budget, the largest above
    // loopback's (65536).
    assert!(sizes[0] <= rpkm_transport::dds_wire::unfragmented_limit(1500));
    assert!(sizes[3] > rpkm_transport::dds_wire::unfragmented_limit(65536));
}

/// Bytes of the reply samples: the serialized sizes (the CDR header and the length
/// included) are 2127 (the Calibrate result a Cyclone DDS client missed), 8195 and 70009, none
/// a multiple of 4, so that the last fragment of each is short and unaligned.
const REPLY_SIZES: [usize; 3] = [2119, 8187, 70001];

/// A reply's stand-in: `n` bytes (CDR `sequence<uint8>`).
#[derive(serde::Serialize, Clone, Debug)]
struct Blob {
    data: Vec<u8>,
}

fn blob(n: usize) -> Blob {
    Blob {
        data: (0..n)
            .map(|i| u8::try_from(i * 7 % 251).expect("below 251"))
            .collect(),
    }
}

fn blob_line(b: &Blob) -> String {
    let mut line = format!("B {} ", b.data.len());
    for x in &b.data {
        let _ = write!(line, "{x:02x}");
    }
    line
}

/// The Cyclone DDS (on the network interface) and Fast DDS readers of the replies.
fn reply_peers(py: &Path, fastdds: &Path) -> [Peer; 2] {
    let count = REPLY_SIZES.len().to_string();
    let mut cyclone = Command::new(py);
    cyclone
        .arg(repo().join("tests/python/large_sample_peer.py"))
        .args([
            "--domain",
            &REPLY_DOMAIN.to_string(),
            "--topic",
            REPLY_TOPIC,
        ])
        .args(["--count", &count, "--timeout", "60", "--blob", "--volatile"]);
    on_network_interface(&mut cyclone);
    let mut fast = Command::new(fastdds);
    fast.args([
        &REPLY_DOMAIN.to_string(),
        REPLY_TOPIC,
        "blob",
        &count,
        "60",
        "volatile",
    ]);
    [
        Peer::start("cyclone", cyclone),
        Peer::start("fastdds", fast),
    ]
}

/// Replies of the size of a Calibrate result and larger, written as the services write a
/// reply on rmw_cyclonedds's mapping (`dds_rpc`: no inline QoS, the request's identity in the
/// payload's header), on a reply topic with rmw's service QoS (reliable, volatile, keep last 10),
/// reach a Cyclone DDS reader and a Fast DDS reader, every byte as sent. (Their payload is a
/// blob, not a GetResult: what decides whether the fragments are read is the inline QoS
/// beside them and how the last one ends.)
#[test]
fn replies_of_several_kilobytes_on_the_cyclone_mapping_reach_cyclone_and_fast_dds() {
    let Some(py) = python() else { return };
    let Some(fastdds) = fastdds_parameters_peer() else {
        return;
    };
    let peers = reply_peers(&py, &fastdds);
    let dp = DomainParticipant::new(REPLY_DOMAIN).expect("participant");
    let qos = QosPolicyBuilder::new()
        .reliability(policy::Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_secs(1),
        })
        .durability(policy::Durability::Volatile)
        .history(policy::History::KeepLast { depth: 10 })
        .build();
    let topic = dp
        .create_topic(
            REPLY_TOPIC.into(),
            "rpkm_test::msg::dds_::Blob_".into(),
            &qos,
            TopicKind::NoKey,
        )
        .expect("topic");
    let writer = dp
        .create_publisher(&qos)
        .expect("publisher")
        .create_datawriter_no_key_cdr::<Blob>(&topic, None)
        .expect("writer");
    // Volatile: write once both sides know each other.
    for peer in &peers {
        assert_eq!(peer.next(), "MATCHED", "{}", peer.name);
    }
    let known = std::time::Instant::now() + TIMEOUT;
    while dp
        .discovered_readers()
        .iter()
        .filter(|r| r.subscription_topic_data.topic_name() == REPLY_TOPIC)
        .count()
        < peers.len()
    {
        assert!(
            std::time::Instant::now() < known,
            "the peers' readers not discovered"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(200));
    for (k, n) in REPLY_SIZES.into_iter().enumerate() {
        let sent = blob(n);
        let bytes = rpkm_msgs::to_cdr(&sent).expect("cdr").len();
        assert_ne!(
            bytes % 4,
            0,
            "{bytes} bytes: the last fragment ends unaligned"
        );
        writer
            .write(sent.clone(), None)
            .unwrap_or_else(|e| panic!("reply {k}: write: {e:?}"));
        for peer in &peers {
            assert!(
                peer.sample() == blob_line(&sent),
                "{} received the {bytes}-byte reply otherwise than sent",
                peer.name
            );
        }
    }
}

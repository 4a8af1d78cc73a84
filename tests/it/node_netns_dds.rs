//! The cross-host case on one machine: two network namespaces joined by a veth pair, made
//! by this test (`ip netns add`, needs root). `ingest` runs in one and publishes the twin
//! stream on DDS only; `tcp_estimator` runs in the other, subscribes on DDS and publishes its
//! estimates on iceoryx2 (shared memory is not namespaced), where this test checks them
//! against the twin's true TCP. The only path between the two nodes is DDS over the veth.
//!
//! Without the privilege the test prints why it skips; with RPKM_REQUIRE_NETNS=1 (a CI that
//! runs as root) a skip is a failure.

use crate::node_support;

use std::collections::HashMap;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use node_support::{rpkm, twin_stream, unique, write_truth_json, Proc, TempDir};
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Transport, TransportConfig};

const N: usize = 300;
const RATE_HZ: f64 = 100.0;
const DOMAIN: &str = "57";

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e}", args.join(" ")))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Two namespaces and a veth pair; deleted on drop.
struct Namespaces {
    a: String,
    b: String,
}

impl Namespaces {
    fn create() -> Result<Namespaces, String> {
        let id = std::process::id() % 100_000;
        let ns = Namespaces {
            a: format!("rpkm_a_{id}"),
            b: format!("rpkm_b_{id}"),
        };
        let (va, vb) = (format!("rva{id}"), format!("rvb{id}"));
        ip(&["netns", "add", &ns.a])?;
        ip(&["netns", "add", &ns.b])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &ns.a])?;
        ip(&["link", "set", &vb, "netns", &ns.b])?;
        let octet = 1 + id % 250;
        for (n, v, host) in [(&ns.a, &va, 1), (&ns.b, &vb, 2)] {
            let addr = format!("10.{}.{octet}.{host}/24", 200 + id % 50);
            ip(&["-n", n, "addr", "add", &addr, "dev", v])?;
            ip(&["-n", n, "link", "set", v, "up", "multicast", "on"])?;
            ip(&["-n", n, "link", "set", "lo", "up"])?;
        }
        Ok(ns)
    }
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}

fn in_ns(ns: &str, args: &[&str], prefix: &str) -> Proc {
    let child = Command::new("ip")
        .args(["netns", "exec", ns, rpkm()])
        .args(args)
        .env("RPKM_IPC_PREFIX", prefix)
        .env("ROS_DOMAIN_ID", DOMAIN)
        .stdout(Stdio::null())
        .spawn()
        .expect("ip netns exec");
    Proc(child)
}

fn skip(reason: &str) {
    assert!(
        std::env::var_os("RPKM_REQUIRE_NETNS").is_none(),
        "RPKM_REQUIRE_NETNS is set but {reason}"
    );
    eprintln!("SKIPPED: {reason}");
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn ingest_and_estimator_in_two_namespaces_over_dds() {
    let uid = Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
        .unwrap_or_default();
    if uid != "0" {
        skip(&format!(
            "creating network namespaces needs root (id -u = {uid:?})"
        ));
        return;
    }
    let ns = match Namespaces::create() {
        Ok(ns) => ns,
        Err(e) => {
            skip(&format!("network namespaces not permitted here: {e}"));
            return;
        }
    };
    let dir = TempDir::new("netns");
    let stream = twin_stream(N, RATE_HZ, |_| 0.0);
    let csv = dir.path("stream.csv");
    std::fs::write(&csv, stream.campaign.to_csv()).expect("write stream");
    let truth = dir.path("truth.json");
    write_truth_json(stream.twin.true_params(), &truth);
    let prefix = unique("netns");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let states_ipc = t.subscriber(&topic::ACTUATOR_STATE).expect("sub");

    let _estimator = in_ns(
        &ns.b,
        &[
            "node",
            "tcp_estimator",
            "--input-backend",
            "dds",
            "--backend",
            "ipc",
            "--param",
            &format!("geometry_file={}", truth.display()),
        ],
        &prefix,
    );
    let _ingest = in_ns(
        &ns.a,
        &[
            "node",
            "ingest",
            "--backend",
            "dds",
            "--source",
            &csv.display().to_string(),
            "--param",
            &format!("rate_hz={RATE_HZ}"),
            "--param",
            "start_delay_s=3",
        ],
        &prefix,
    );
    let by_stamp: HashMap<_, _> = stream
        .campaign
        .poses
        .iter()
        .enumerate()
        .filter_map(|(k, p)| Some((stamp_from_seconds(p.t)?, k)))
        .collect();
    let mut seen = Vec::new();
    let mut worst = 0.0f64;
    let deadline = Instant::now() + Duration::from_secs(40);
    while Instant::now() < deadline && seen.last() != Some(&(N - 1)) {
        assert!(
            states_ipc.try_recv().expect("recv").is_none(),
            "ingest must not reach the estimator over iceoryx2"
        );
        match estimates.try_recv().expect("recv") {
            Some(e) => {
                let k = *by_stamp.get(&e.stamp).expect("a stream stamp");
                let tcp = stream.truth[k].tcp;
                worst = worst.max((e.x - tcp.x / 1e3).abs().max((e.y - tcp.y / 1e3).abs()));
                seen.push(k);
            }
            None => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    assert!(
        seen.len() >= N * 9 / 10,
        "estimates for {} of {N} samples crossed the veth (best-effort stream)",
        seen.len()
    );
    assert_eq!(seen.last(), Some(&(N - 1)), "the stream reached its end");
    assert!(seen.windows(2).all(|w| w[1] > w[0]), "in order");
    assert!(worst < 1e-9, "estimates match the twin's truth: {worst} m");
}

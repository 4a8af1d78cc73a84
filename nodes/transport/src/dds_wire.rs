//! What goes on the wire beside a sample, where it decides whether a peer can read it.
//!
//! RustDDS (0.15.1) sends a sample as one DATA submessage when it fits the datagram budget of
//! the reader's path (the interface MTU less 128 bytes of headers for a reliable writer, see
//! [`unfragmented_limit`]), and as DATA_FRAG submessages (256-byte fragments, several per
//! submessage) when it does not. Fragments of a sample without inline QoS are well formed:
//! Cyclone DDS and Fast DDS reassemble them. Fragments of a sample *with* inline QoS are not:
//! RustDDS writes the DATA_FRAG's inline QoS parameter list behind a one-byte presence tag
//! (its serializer's encoding of an optional value), a byte the submessage's length does not
//! count. A reader then sees the parameter id `0x8301` and the length `0x1800` (6144) where
//! `PID_RELATED_SAMPLE_IDENTITY` (`0x0083`) and 24 stand, and drops every fragment as
//! malformed (Cyclone DDS: "plist(vendor 1.18): quickscan: parameter length 6144 out of
//! bounds"); the writer resends them forever.
//!
//! The only inline QoS rpkm's samples carry is a reply's related sample identity (DDS-RPC).
//! Topics carry none, so a Parameters or a Diagnosis of any size crosses. A reply crosses at
//! any size when it carries none: the services ([`crate::dds_rpc`]) give it only to replies
//! on the mapping that reads it (rmw_fastrtps's); rmw_cyclonedds's mapping has the request's
//! identity in the payload's header and never looks at the inline QoS. A reply that must
//! carry it reaches its client only whole: up to [`unfragmented_limit`] of the client's path
//! (any size on loopback), and the server says so where a reply is larger than
//! [`inline_qos_limit`].

/// Headers RustDDS takes from a path's MTU before a reliable writer's sample: IPv4, UDP and
/// the RTPS header (48), a heartbeat kept free behind the sample (32), the DATA submessage's
/// own fields (48).
const HEADERS: usize = 48 + 32 + 48;

/// The largest serialized sample that may carry inline QoS from this machine: the
/// [`unfragmented_limit`] of the smallest MTU a reader's path can have here, the MTU of the
/// machine's network interfaces that are up (not loopback), at most 1500 (what RustDDS
/// assumes for a reader on no local subnet). Without such an interface every reader is on
/// loopback. Read from `/sys/class/net` (Linux); elsewhere the 1500-byte figure.
pub fn inline_qos_limit() -> usize {
    unfragmented_limit(smallest_path_mtu(std::path::Path::new("/sys/class/net")))
}

/// Ethernet's MTU: what RustDDS assumes for a reader's path when it knows no better.
const ETHERNET_MTU: u32 = 1500;
/// Linux's loopback MTU.
const LOOPBACK_MTU: u32 = 65536;

/// The smallest MTU of the interfaces under `sys_class_net` that are up, loopback left
/// out, at most [`ETHERNET_MTU`]; [`LOOPBACK_MTU`] where there is none.
fn smallest_path_mtu(sys_class_net: &std::path::Path) -> u32 {
    let Ok(entries) = std::fs::read_dir(sys_class_net) else {
        return ETHERNET_MTU;
    };
    let read = |dir: &std::path::Path, name: &str| {
        std::fs::read_to_string(dir.join(name)).map(|s| s.trim().to_owned())
    };
    let mtus: Vec<u32> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|dir| dir.file_name().is_some_and(|n| n != "lo"))
        .filter(|dir| read(dir, "operstate").is_ok_and(|s| s == "up"))
        .filter_map(|dir| read(&dir, "mtu").ok()?.parse().ok())
        .collect();
    match mtus.iter().min() {
        Some(&mtu) => mtu.min(ETHERNET_MTU),
        None => LOOPBACK_MTU,
    }
}

/// The largest serialized sample (CDR encapsulation header included) RustDDS sends to a
/// reliable reader as one DATA on a path whose MTU is `path_mtu`: 1372 bytes on 1500-byte
/// Ethernet, 65408 on Linux's loopback (65536). RustDDS takes the MTU of the local interface
/// whose subnet holds each of the reader's unicast addresses, the smallest over them, and
/// 1500 where none does. Above this limit a sample goes as fragments, which a reader can
/// read only when the sample has no inline QoS.
pub fn unfragmented_limit(path_mtu: u32) -> usize {
    usize::try_from(path_mtu)
        .unwrap_or(usize::MAX)
        .saturating_sub(HEADERS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn interface(dir: &std::path::Path, name: &str, state: &str, mtu: u32) {
        let d = dir.join(name);
        std::fs::create_dir_all(&d).expect("dir");
        std::fs::write(d.join("operstate"), format!("{state}\n")).expect("operstate");
        std::fs::write(d.join("mtu"), format!("{mtu}\n")).expect("mtu");
    }

    #[test]
    fn the_smallest_path_mtu_is_the_smallest_interface_up_at_most_ethernet() {
        let dir = tempfile::tempdir().expect("tempdir");
        interface(dir.path(), "lo", "unknown", 65536);
        assert_eq!(smallest_path_mtu(dir.path()), 65536, "loopback only");
        interface(dir.path(), "eth0", "up", 9000);
        assert_eq!(
            smallest_path_mtu(dir.path()),
            1500,
            "a jumbo interface, readers elsewhere"
        );
        interface(dir.path(), "eth1", "up", 1400);
        interface(dir.path(), "ifb0", "down", 1280);
        assert_eq!(smallest_path_mtu(dir.path()), 1400, "eth1; ifb0 is down");
        assert_eq!(smallest_path_mtu(&dir.path().join("none")), 1500, "no /sys");
    }

    #[test]
    fn the_unfragmented_limit_follows_the_path_mtu() {
        assert_eq!(unfragmented_limit(1500), 1372);
        assert_eq!(unfragmented_limit(65536), 65408);
        assert_eq!(unfragmented_limit(100), 0);
    }
}

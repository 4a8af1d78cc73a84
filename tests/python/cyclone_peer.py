#!/usr/bin/env python3
"""Independent DDS peer (Eclipse Cyclone DDS, PyPI `cyclonedds`) for the interop test.

Two modes, both on the ROS 2 DDS mapping (topic rt/rpkm/..., type rpkm_msgs::msg::dds_::X_,
XCDR1 little-endian):

  sub_estimate  --domain D --count N --timeout S
      Subscribes to /rpkm/tcp_estimate, checks every TcpEstimate with seq 1..N against
      expected_estimate(seq), prints one JSON line per first-seen seq, then "DONE".
      Exit 0 when all N were seen and correct, 1 on a wrong value, 2 on timeout.

  print_estimate  --domain D --count N --timeout S
      As sub_estimate, reading what a launched stack estimates: every TcpEstimate with seq
      1..N printed as one JSON line (first seen), no expected values; then "DONE".

  pub_actuator  --domain D --count N --timeout S [--topic T] [--bad] [--fresh-rounds]
      Publishes ActuatorState seq 1..N (values from expected_actuator(seq)) on
      /rpkm/actuator_state (or T), the whole set every 50 ms until killed or timeout (exit 0);
      with --bad also seq N+1 (a NaN position) and N+2 (a position out of range). It writes
      once a reader has matched, and 0.5 s later. With --fresh-rounds, round r has seqs
      (r-1)(N+2)+1.. and ends with its last good sample repeated (out of order), so that a
      reader that joins mid-round still sees every later sample once.

Run with the venv made by `python3 -m venv .venv && .venv/bin/pip install cyclonedds`.
Discovery is restricted to loopback (interface lo, no multicast, peer 127.0.0.1): without it
Cyclone took about 7 s to match RustDDS here, with it about 0.1 s.
"""

import argparse
import json
import os
import struct
import sys
import time
from dataclasses import dataclass

import loopback  # noqa: E402,F401  (before cyclonedds: the loopback configuration)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class ActuatorState(IdlStruct, typename="rpkm_msgs::msg::dds_::ActuatorState_"):
    stamp: Time
    seq: t.uint64
    position: t.array[t.float64, 4]
    force: t.array[t.float64, 4]
    follower: t.array[bool, 4]
    covariate_count: t.uint8
    covariates: t.array[t.float64, 8]


@dataclass
class TcpEstimate(IdlStruct, typename="rpkm_msgs::msg::dds_::TcpEstimate_"):
    stamp: Time
    seq: t.uint64
    x: t.float64
    y: t.float64
    psi: t.float64
    loop_residuals: t.array[t.float64, 5]
    rod_forces: t.array[t.float64, 5]
    drive_forces: t.array[t.float64, 4]
    iterations: t.uint32
    model: t.uint8
    converged: bool
    outcome: t.uint8
    reason: t.uint8


# The same formulas as in nodes/transport/tests/dds_cyclone_interop.rs.
def expected_estimate(seq):
    s = float(seq)
    return TcpEstimate(
        stamp=Time(sec=1000 + seq, nanosec=seq * 1000),
        seq=seq,
        x=s * 1e-3,
        y=1.7 + s * 1e-4,
        psi=-s * 1e-6,
        loop_residuals=[s * 1e-9, 2e-9, 3e-9, 4e-9, 0.0],
        rod_forces=[s, -s, 100.0, -100.0, 0.5],
        drive_forces=[1.0, 2.0, -3.0, s],
        iterations=seq + 2,
        model=29,
        converged=seq % 2 == 0,
        outcome=seq % 3,
        reason=seq % 7,
    )


def expected_actuator(seq):
    s = float(seq)
    return ActuatorState(
        stamp=Time(sec=2000 + seq, nanosec=7 * seq),
        seq=seq,
        position=[2.6110556 + s * 1e-6, 2.6110556, 0.7889444, 0.7889444 - s * 1e-6],
        force=[s, -2.0 * s, 0.0, 8600.0],
        follower=[False, seq % 2 == 1, seq % 3 == 0, False],
        covariate_count=2,
        covariates=[21.5 + s, 22.25, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    )


def bits(v):
    """The IEEE 754 bit pattern of a float64, so that the Rust side compares exactly."""
    return struct.unpack("<Q", struct.pack("<d", v))[0]


def as_dict(msg):
    """Integers as they are, float64s as their bit patterns (see bits)."""
    return {
        "stamp": [msg.stamp.sec, msg.stamp.nanosec],
        "seq": msg.seq,
        "x": bits(msg.x),
        "y": bits(msg.y),
        "psi": bits(msg.psi),
        "loop_residuals": [bits(v) for v in msg.loop_residuals],
        "rod_forces": [bits(v) for v in msg.rod_forces],
        "drive_forces": [bits(v) for v in msg.drive_forces],
        "iterations": msg.iterations,
        "model": msg.model,
        "converged": bool(msg.converged),
        "outcome": msg.outcome,
        "reason": msg.reason,
    }


def sub_estimate(args):
    dp = DomainParticipant(args.domain)
    topic = Topic(dp, "rt/rpkm/tcp_estimate", TcpEstimate)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(64))
    reader = DataReader(dp, topic, qos=qos)
    print("READY", flush=True)
    seen = set()
    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline:
        for msg in reader.take(N=64):
            if not isinstance(msg, TcpEstimate) or msg.seq in seen or not 1 <= msg.seq <= args.count:
                continue
            d = as_dict(msg)
            print(json.dumps(d), flush=True)
            if args.mode == "sub_estimate" and d != as_dict(expected_estimate(msg.seq)):
                print(f"MISMATCH seq {msg.seq}: {d}", flush=True)
                return 1
            seen.add(msg.seq)
        if len(seen) == args.count:
            print("DONE", flush=True)
            return 0
        time.sleep(0.005)
    print(f"TIMEOUT after {args.timeout} s: saw seq {sorted(seen)}", flush=True)
    return 2


def bad_actuators(first, count):
    """Samples ingest must reject: a NaN position (seq first+count), a position 10 km out of
    range (first+count+1); both after the good ones, so only their own fault rejects them."""
    nan = expected_actuator(first + count)
    nan.position = [nan.position[0], float("nan"), nan.position[2], nan.position[3]]
    far = expected_actuator(first + count + 1)
    far.position = [1.0e4, far.position[1], far.position[2], far.position[3]]
    return [nan, far]


def wait_matched(writer, deadline):
    """Until Cyclone has matched a reader, then a settling pause: the match is one direction of
    discovery, the reader learning of this writer is the other, and a sample written before
    it is lost to a volatile reader (the CI once saw a round without its seq 1)."""
    while time.monotonic() < deadline and not writer.get_matched_subscriptions():
        time.sleep(0.01)
    time.sleep(0.5)


def pub_actuator(args):
    dp = DomainParticipant(args.domain)
    topic = Topic(dp, "rt/" + args.topic.lstrip("/"), ActuatorState)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(64))
    writer = DataWriter(dp, topic, qos=qos)
    print("READY", flush=True)
    deadline = time.monotonic() + args.timeout
    wait_matched(writer, deadline)
    first = 1
    while time.monotonic() < deadline:
        for seq in range(first, first + args.count):
            writer.write(expected_actuator(seq))
        if args.bad:
            for msg in bad_actuators(first, args.count):
                writer.write(msg)
        if args.fresh_rounds:
            # The round's last good sample once more: out of order by its repeated seq.
            writer.write(expected_actuator(first + args.count - 1))
            first += args.count + 2
        time.sleep(0.05)
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mode", choices=["sub_estimate", "print_estimate", "pub_actuator"])
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    p.add_argument("--count", type=int, default=10)
    p.add_argument("--timeout", type=float, default=20.0)
    p.add_argument("--topic", default="/rpkm/actuator_state",
                   help="ROS topic of pub_actuator (ingest listens on /rpkm/controller/actuator_state)")
    p.add_argument("--fresh-rounds", action="store_true",
                   help="pub_actuator: each round continues the seqs (N+2 further on) and ends with "
                        "its last good sample repeated, instead of repeating seq 1..N")
    p.add_argument("--bad", action="store_true",
                   help="pub_actuator: also publish a NaN and an out-of-range sample after the good ones")
    args = p.parse_args()
    return pub_actuator(args) if args.mode == "pub_actuator" else sub_estimate(args)


if __name__ == "__main__":
    sys.exit(main())

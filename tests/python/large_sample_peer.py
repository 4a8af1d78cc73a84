#!/usr/bin/env python3
"""Independent reader of large samples (Eclipse Cyclone DDS, PyPI `cyclonedds`): reads
rpkm_msgs/Parameters (or a blob of bytes) on a DDS topic and prints each sample it receives
as one line, in the form tests/cpp/fastdds_parameters_peer.cpp prints it (so that the Rust
test compares both peers with what it sent, float64s as their bit patterns):

  S MODEL COUNT NAMES VALUES SIGMAS EFFECTS EFFECT_NAMES EFFECT_VALUES CAL VAL MAX COND
  B LENGTH HEX

lists comma-separated (`-` when empty), floats as 16 hex digits of their IEEE 754 bits.

  large_sample_peer.py --domain D --topic T --count N --timeout S [--blob] [--volatile]

T is the DDS topic (rt/rpkm/parameters); the reader is reliable, transient local (volatile
with --volatile, as a service client's reply reader), keep last 16. Prints READY once the reader exists, MATCHED once it has matched a writer, a line per
sample, then DONE n. Exit 0 when N
samples arrived, 2 on timeout.

Which interface Cyclone uses is the environment's CYCLONEDDS_URI (tests/python/loopback.py
when unset): the test names the machine's own network interface to make the samples take the
path a cell's peer takes, where a few kB no longer fit one datagram.
"""

import argparse
import struct
import sys
import time
from dataclasses import dataclass

import loopback  # noqa: E402,F401  (before cyclonedds: the loopback configuration)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Parameters(IdlStruct, typename="rpkm_msgs::msg::dds_::Parameters_"):
    model: t.uint8
    names: t.sequence[str]
    values: t.sequence[t.float64]
    sigmas: t.sequence[t.float64]
    active_effects: t.sequence[str]
    effect_parameter_names: t.sequence[str]
    effect_parameter_values: t.sequence[t.float64]
    measurement_count: t.uint32
    cal_rms: t.float64
    val_rms: t.float64
    max_abs_residual: t.float64
    condition_number: t.float64


@dataclass
class Blob(IdlStruct, typename="rpkm_test::msg::dds_::Blob_"):
    """A payload of any length: the tests' stand-in for a reply or a long message."""
    data: t.sequence[t.uint8]


def bits(v):
    return "%016x" % struct.unpack("<Q", struct.pack("<d", v))[0]


def words(items):
    return ",".join(items) if items else "-"


def line(p):
    if isinstance(p, Blob):
        return f"B {len(p.data)} {bytes(p.data).hex() or '-'}"
    return " ".join(
        [
            "S",
            str(p.model),
            str(p.measurement_count),
            words(p.names),
            words([bits(v) for v in p.values]),
            words([bits(v) for v in p.sigmas]),
            words(p.active_effects),
            words(p.effect_parameter_names),
            words([bits(v) for v in p.effect_parameter_values]),
            bits(p.cal_rms),
            bits(p.val_rms),
            bits(p.max_abs_residual),
            bits(p.condition_number),
        ]
    )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--topic", required=True)
    ap.add_argument("--count", type=int, required=True)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--volatile", action="store_true")
    ap.add_argument("--blob", action="store_true")
    args = ap.parse_args()
    dp = DomainParticipant(args.domain)
    kind = Blob if args.blob else Parameters
    topic = Topic(dp, args.topic, kind)
    qos = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.Durability.Volatile if args.volatile else Policy.Durability.TransientLocal,
        Policy.History.KeepLast(16),
    )
    reader = DataReader(dp, topic, qos=qos)
    print("READY", flush=True)
    got = 0
    matched = False
    deadline = time.monotonic() + args.timeout
    while got < args.count and time.monotonic() < deadline:
        if not matched and reader.get_matched_publications():
            matched = True
            print("MATCHED", flush=True)
        for p in reader.take(N=16):
            if isinstance(p, kind):
                print(line(p), flush=True)
                got += 1
        time.sleep(0.01)
    print(f"DONE {got}", flush=True)
    sys.exit(0 if got >= args.count else 2)


if __name__ == "__main__":
    main()

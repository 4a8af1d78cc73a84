#!/usr/bin/env python3
"""Independent DDS peer (Eclipse Cyclone DDS) for the standard views of the rpkm nodes.

    ros2_views_peer.py --domain D --count N --timeout S

Subscribes, as RViz, Foxglove or tf2 would on rmw_cyclonedds (topic rt/..., type
pkg::msg::dds_::X_, XCDR1 little endian, reliable), to
  /rpkm/tcp_pose  geometry_msgs/PoseStamped
  /tf             tf2_msgs/TFMessage
  /joint_states   sensor_msgs/JointState
with the types defined here from the ROS 2 .msg files, not from rpkm. Prints one JSON line
per sample ({"pose": ...}, {"tf": ...}, {"joint": ...}; float64s as their IEEE 754 bit
patterns, so that the Rust side compares exactly), then "DONE" once N of each arrived
(exit 0), or "TIMEOUT ..." (exit 2).
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
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header
    pose: Pose


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: t.sequence[TransformStamped]


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: t.sequence[str]
    position: t.sequence[t.float64]
    velocity: t.sequence[t.float64]
    effort: t.sequence[t.float64]


def bits(v):
    """The IEEE 754 bit pattern of a float64."""
    return struct.unpack("<Q", struct.pack("<d", v))[0]


def header(h):
    return {"stamp": [h.stamp.sec, h.stamp.nanosec], "frame_id": h.frame_id}


def quaternion(q):
    return [bits(q.x), bits(q.y), bits(q.z), bits(q.w)]


def pose(m):
    p = m.pose.position
    return {"header": header(m.header), "position": [bits(p.x), bits(p.y), bits(p.z)],
            "orientation": quaternion(m.pose.orientation)}


def tf(m):
    out = []
    for ts in m.transforms:
        v = ts.transform.translation
        out.append({"header": header(ts.header), "child_frame_id": ts.child_frame_id,
                    "translation": [bits(v.x), bits(v.y), bits(v.z)],
                    "rotation": quaternion(ts.transform.rotation)})
    return out


def joint(m):
    return {"header": header(m.header), "name": list(m.name),
            "position": [bits(v) for v in m.position],
            "velocity": [bits(v) for v in m.velocity],
            "effort": [bits(v) for v in m.effort]}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    p.add_argument("--count", type=int, default=10)
    p.add_argument("--timeout", type=float, default=60.0)
    args = p.parse_args()
    dp = DomainParticipant(args.domain)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100))
    views = [
        ("pose", DataReader(dp, Topic(dp, "rt/rpkm/tcp_pose", PoseStamped), qos=qos), pose),
        ("tf", DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=qos), tf),
        ("joint", DataReader(dp, Topic(dp, "rt/joint_states", JointState), qos=qos), joint),
    ]
    print("READY", flush=True)
    seen = {name: 0 for name, _, _ in views}
    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline:
        for name, reader, convert in views:
            for msg in reader.take(N=100):
                if not hasattr(msg, "header") and not hasattr(msg, "transforms"):
                    continue  # a sample info without data
                print(json.dumps({name: convert(msg)}), flush=True)
                seen[name] += 1
        if all(n >= args.count for n in seen.values()):
            print("DONE", flush=True)
            return 0
        time.sleep(0.005)
    print(f"TIMEOUT after {args.timeout} s: {seen}", flush=True)
    return 2


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Independent ros2_control cell (Eclipse Cyclone DDS, PyPI `cyclonedds`) for
tests/it/node_joint_states.rs: plays a script of sensor_msgs/JointState and
sensor_msgs/Temperature messages as a joint_state_broadcaster and a thermometer publish them on
rmw_cyclonedds (topic rt/..., type pkg::msg::dds_::X_, XCDR1), and sets parameters through
an rpkm node's parameter services as `ros2 param set` does (ros2_params_peer.Peer).

    joint_states_peer.py SCRIPT --domain D [--rate HZ] [--timeout S] [--best-effort]

--best-effort: the writers offer best effort reliability (a reliable reader matches none).

SCRIPT, one step a line (fields separated by spaces, lists by commas, `-` an empty list):
  J SEC NANOSEC NAMES POSITIONS VELOCITIES EFFORTS   a JointState on /joint_states; the J
                                                     lines are paced at --rate (default 1 kHz)
  T TOPIC SEC NANOSEC CELSIUS                        a Temperature on TOPIC (not paced)
  MATCH N TOPIC...                                   wait until N readers of each topic
                                                     matched (then 0.5 s: the other
                                                     direction of discovery)
  SET NODE KEY VALUE                                 set string parameter KEY of NODE
                                                     (`''` is the empty string); prints
                                                     "SET KEY ok" or "SET KEY refused: why"
                                                     once the reply came, the pacing starts
                                                     again after it
  WAIT SECONDS                                       pause (the pacing starts again after it)
Numbers are Python floats (`nan` is NaN). Prints "PLAYED n" (JointStates written) at the end;
exit 0, or 2 on a timeout.
"""

import argparse
import os
import sys
import time
from dataclasses import dataclass

import loopback  # noqa: E402,F401  (before cyclonedds: the loopback configuration)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from ros2_params_peer import Peer  # noqa: E402
from ros2_views_peer import Header, JointState, Time  # noqa: E402


@dataclass
class Temperature(IdlStruct, typename="sensor_msgs::msg::dds_::Temperature_"):
    header: Header
    temperature: t.float64
    variance: t.float64


def floats(field):
    return [] if field == "-" else [float(v) for v in field.split(",")]


class Cell:
    def __init__(self, domain, rate, deadline, best_effort=False):
        self.dp = DomainParticipant(domain)
        self.period = 1.0 / rate
        self.deadline = deadline
        # the broadcaster's default QoS (SystemDefaultsQoS: reliable, volatile, keep last)
        self.reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                            Policy.History.KeepLast(1000))
        if best_effort:
            self.reliable = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1000))
        self.writers = {}
        self.peers = {}
        self.played = 0
        self.restart()

    def restart(self):
        self.t0 = time.monotonic()
        self.k = 0

    def writer(self, topic, kind):
        if topic not in self.writers:
            tp = Topic(self.dp, "rt/" + topic.lstrip("/"), kind)
            self.writers[topic] = DataWriter(self.dp, tp, qos=self.reliable)
        return self.writers[topic]

    def joint_state(self, f):
        names = [] if f[3] == "-" else f[3].split(",")
        msg = JointState(Header(Time(int(f[1]), int(f[2])), ""), names, floats(f[4]),
                         floats(f[5]), floats(f[6]))
        # paced: the k-th state of a run k periods after its start (a sleep, then a short spin)
        due = self.t0 + self.k * self.period
        ahead = due - time.monotonic()
        if ahead > 3e-4:
            time.sleep(ahead - 2e-4)
        while time.monotonic() < due:
            pass
        self.writer("/joint_states", JointState).write(msg)
        self.k += 1
        self.played += 1

    def match(self, count, topics):
        for topic in topics:
            kind = JointState if topic == "/joint_states" else Temperature
            w = self.writer(topic, kind)
            while len(w.get_matched_subscriptions()) < count:
                if time.monotonic() > self.deadline:
                    raise TimeoutError(f"fewer than {count} readers of {topic} matched")
                time.sleep(0.01)
        time.sleep(0.5)

    def set(self, node, key, value):
        if node not in self.peers:
            self.peers[node] = Peer(self.dp.domain_id, node, self.deadline)
        value = "" if value == "''" else value
        reply = self.peers[node].step({"set": {key: value}})["set"][key]
        print(f"SET {key} " + ("ok" if reply[0] else f"refused: {reply[1]}"), flush=True)

    def step(self, line):
        f = line.split()
        if not f:
            return
        if f[0] == "J":
            self.joint_state(f)
        elif f[0] == "T":
            msg = Temperature(Header(Time(int(f[2]), int(f[3])), "thermometer"), float(f[4]), 0.0)
            self.writer(f[1], Temperature).write(msg)
        elif f[0] == "MATCH":
            self.match(int(f[1]), f[2:])
            self.restart()
        elif f[0] == "SET":
            self.set(f[1], f[2], f[3])
            self.restart()
        elif f[0] == "WAIT":
            time.sleep(float(f[1]))
            self.restart()
        else:
            raise ValueError(f"unknown step {line!r}")


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("script")
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    p.add_argument("--rate", type=float, default=1000.0)
    p.add_argument("--timeout", type=float, default=60.0)
    p.add_argument("--best-effort", action="store_true")
    args = p.parse_args()
    cell = Cell(args.domain, args.rate, time.monotonic() + args.timeout, args.best_effort)
    try:
        with open(args.script) as f:
            for line in f:
                cell.step(line)
    except TimeoutError as e:
        print(f"TIMEOUT {e}", flush=True)
        return 2
    print(f"PLAYED {cell.played}", flush=True)
    # the last samples reach the readers before the writers go (reliable, volatile)
    time.sleep(1.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())

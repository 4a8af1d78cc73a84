#!/usr/bin/env python3
"""Independent lifecycle client (Eclipse Cyclone DDS, PyPI `cyclonedds`) of an rpkm node, as
`ros2 lifecycle` on rmw_cyclonedds speaks to a managed node: the services
`~/change_state`, `~/get_state`, `~/get_available_transitions` (types
`lifecycle_msgs::srv::dds_::X_Request_` / `_Response_`, rmw_cyclonedds's 16-byte header
first) and the topic `~/transition_event` (`lifecycle_msgs::msg::dds_::TransitionEvent_`),
written from the .msg/.srv definitions of ROS 2's lifecycle_msgs; besides, the node's
estimates on `/rpkm/tcp_estimate` (or, `--watch actuator_state`, ingest's drive states on
`/rpkm/actuator_state`).

  lifecycle_peer.py --domain D --node /rpkm/tcp_estimator --dwell S --timeout S \
      [--watch tcp_estimate|actuator_state] configure activate deactivate cleanup shutdown

For each transition, in order: ChangeState by id, then GetState and GetAvailableTransitions,
then S seconds in that state. Prints one JSON object: "steps" (transition, success, state
after, transitions offered), "events" (every TransitionEvent of the node: transition id and
label, start and goal state ids, timestamp), "estimates_before_activate" (estimates received
before the activate request was sent), "estimate_stamps" (ns of every estimate received),
"received_ns" (the wall-clock ns at which each was received).
Exit 0, or 2 on a timeout.
"""

import argparse
import json
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

from cyclone_peer import ActuatorState, TcpEstimate  # noqa: E402

MSG = "lifecycle_msgs::msg::dds_::"
SRV = "lifecycle_msgs::srv::dds_::"
CLIENT_ID = 0x5250_4B4D_6C69_6665  # "RPKMlife": any id, echoed by the server
IDS = {"configure": 1, "cleanup": 2, "activate": 3, "deactivate": 4}
SHUTDOWN_FROM = {1: 5, 2: 6, 3: 7}  # unconfigured_shutdown, inactive_, active_


@dataclass
class State(IdlStruct, typename=MSG + "State_"):
    id: t.uint8
    label: str


@dataclass
class Transition(IdlStruct, typename=MSG + "Transition_"):
    id: t.uint8
    label: str


@dataclass
class TransitionDescription(IdlStruct, typename=MSG + "TransitionDescription_"):
    transition: Transition
    start_state: State
    goal_state: State


@dataclass
class TransitionEvent(IdlStruct, typename=MSG + "TransitionEvent_"):
    timestamp: t.uint64
    transition: Transition
    start_state: State
    goal_state: State


@dataclass
class ChangeStateRequest(IdlStruct, typename=SRV + "ChangeState_Request_"):
    client: t.uint64
    seq: t.int64
    transition: Transition


@dataclass
class ChangeStateResponse(IdlStruct, typename=SRV + "ChangeState_Response_"):
    client: t.uint64
    seq: t.int64
    success: bool


@dataclass
class GetStateRequest(IdlStruct, typename=SRV + "GetState_Request_"):
    client: t.uint64
    seq: t.int64
    structure_needs_at_least_one_member: t.uint8


@dataclass
class GetStateResponse(IdlStruct, typename=SRV + "GetState_Response_"):
    client: t.uint64
    seq: t.int64
    current_state: State


@dataclass
class GetTransitionsRequest(IdlStruct, typename=SRV + "GetAvailableTransitions_Request_"):
    client: t.uint64
    seq: t.int64
    structure_needs_at_least_one_member: t.uint8


@dataclass
class GetTransitionsResponse(IdlStruct, typename=SRV + "GetAvailableTransitions_Response_"):
    client: t.uint64
    seq: t.int64
    available_transitions: t.sequence[TransitionDescription]


class Peer:
    def __init__(self, domain, node, deadline, watch="tcp_estimate"):
        self.dp = DomainParticipant(domain)
        self.deadline = deadline
        self.seq = 0
        reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                       Policy.History.KeepLast(10))
        self.services = {}
        for name, req, resp in [("change_state", ChangeStateRequest, ChangeStateResponse),
                                ("get_state", GetStateRequest, GetStateResponse),
                                ("get_available_transitions", GetTransitionsRequest,
                                 GetTransitionsResponse)]:
            rq = Topic(self.dp, f"rq{node}/{name}Request", req)
            rr = Topic(self.dp, f"rr{node}/{name}Reply", resp)
            self.services[name] = (DataWriter(self.dp, rq, qos=reliable),
                                   DataReader(self.dp, rr, qos=reliable))
        events = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100))
        self.events = DataReader(self.dp, Topic(self.dp, f"rt{node}/transition_event",
                                                TransitionEvent), qos=events)
        estimates = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                        Policy.History.KeepLast(1024))
        self.watched = {"tcp_estimate": TcpEstimate, "actuator_state": ActuatorState}[watch]
        if watch == "actuator_state":
            # the drive states go out best effort (a reliable reader would not match)
            estimates = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1024))
        self.estimates = DataReader(self.dp, Topic(self.dp, f"rt/rpkm/{watch}", self.watched),
                                    qos=estimates)
        self.seen_events = []
        self.stamps = []
        self.received = []

    def poll(self):
        for e in self.events.take(N=64):
            if isinstance(e, TransitionEvent):
                self.seen_events.append({
                    "transition": [e.transition.id, e.transition.label],
                    "start": e.start_state.id, "goal": e.goal_state.id,
                    "timestamp": e.timestamp})
        for m in self.estimates.take(N=1024):
            if isinstance(m, self.watched):
                self.received.append(time.time_ns())
                self.stamps.append(m.stamp.sec * 1_000_000_000 + m.stamp.nanosec)

    def call(self, name, make_request):
        w, r = self.services[name]
        while not (w.get_matched_subscriptions() and r.get_matched_publications()):
            if time.monotonic() > self.deadline:
                raise TimeoutError(f"{name}: the service was not discovered")
            self.poll()
            time.sleep(0.02)
        self.seq += 1
        seq = self.seq
        w.write(make_request(seq))
        # one request: a change of state must not be sent twice
        while time.monotonic() < self.deadline:
            for reply in r.take(N=16):
                if getattr(reply, "client", None) == CLIENT_ID and reply.seq == seq:
                    return reply
            self.poll()
            time.sleep(0.005)
        raise TimeoutError(f"{name}: no reply to request {seq}")

    def dwell(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.poll()
            time.sleep(0.01)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--node", required=True)
    ap.add_argument("--dwell", type=float, default=1.5)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--watch", choices=["tcp_estimate", "actuator_state"], default="tcp_estimate")
    ap.add_argument("transitions", nargs="+")
    a = ap.parse_args()
    peer = Peer(a.domain, a.node, time.monotonic() + a.timeout, a.watch)
    out = {"steps": [], "estimates_before_activate": None}
    state = peer.call("get_state", lambda q: GetStateRequest(CLIENT_ID, q, 0)).current_state.id
    out["initial_state"] = state
    peer.dwell(a.dwell)
    for name in a.transitions:
        tid = SHUTDOWN_FROM[state] if name == "shutdown" else IDS[name]
        if name == "activate" and out["estimates_before_activate"] is None:
            peer.poll()
            out["estimates_before_activate"] = len(peer.stamps)
        ok = peer.call("change_state",
                       lambda q: ChangeStateRequest(CLIENT_ID, q, Transition(tid, ""))).success
        state = peer.call("get_state",
                          lambda q: GetStateRequest(CLIENT_ID, q, 0)).current_state.id
        offered = [d.transition.id for d in peer.call(
            "get_available_transitions",
            lambda q: GetTransitionsRequest(CLIENT_ID, q, 0)).available_transitions]
        out["steps"].append({"transition": name, "success": ok, "state": state,
                             "offered": offered})
        peer.dwell(a.dwell)
    peer.poll()
    out["events"] = peer.seen_events
    out["estimate_stamps"] = peer.stamps
    out["received_ns"] = peer.received
    print(json.dumps(out))


if __name__ == "__main__":
    try:
        main()
    except TimeoutError as e:
        print(json.dumps({"error": str(e)}))
        sys.exit(2)

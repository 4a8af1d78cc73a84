#!/usr/bin/env python3
"""Independent ROS 2 parameter client (Eclipse Cyclone DDS, PyPI `cyclonedds`) for
tests/it/node_ros2_params.rs: speaks to an rpkm node as `ros2 param` on rmw_cyclonedds does.

The services are DDS topic pairs `rq/<node>/<service>Request` and `rr/<node>/<service>Reply`
with types `rcl_interfaces::srv::dds_::<Service>_Request_` / `_Response_`. rmw_cyclonedds
writes a 16-byte header before the request, the client's id (uint64) and the request's
sequence number (int64), and expects it back in the reply: here it is the first two members
of each struct, and a reply is taken only when both match.

  ros2_params_peer.py --domain D --node /rpkm/preload_monitor --timeout S SCRIPT.json

SCRIPT is a list of steps, each {"get": [names]} or {"set": {name: value}} or
{"set_atomically": {name: value}} or {"describe": [names]} or {"list": true}, or
{"first_calls": N, "get": [names]} (N fresh clients, each a participant of its own with a
new request writer and reply reader, calling get_parameters ONCE as soon as both are
matched, as a one-shot `ros2 param get` process does: no resend; prints how many got their
reply within 3 s), or
{"await_event": name} (a /parameter_events message of the node changing `name`) or
{"await_rosout": text} (a /rosout record of the node whose msg contains `text`).
Values: a Python float is a double, int an integer, bool a bool, str a string. One JSON
line per step is printed with what came back; exit 0 when all steps ran, 2 on a timeout.
"""

import argparse
import json
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
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

MSG = "rcl_interfaces::msg::dds_::"
SRV = "rcl_interfaces::srv::dds_::"


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class ParameterValue(IdlStruct, typename=MSG + "ParameterValue_"):
    type: t.uint8
    bool_value: bool
    integer_value: t.int64
    double_value: t.float64
    string_value: str
    byte_array_value: t.sequence[t.uint8]
    bool_array_value: t.sequence[bool]
    integer_array_value: t.sequence[t.int64]
    double_array_value: t.sequence[t.float64]
    string_array_value: t.sequence[str]


@dataclass
class Parameter(IdlStruct, typename=MSG + "Parameter_"):
    name: str
    value: ParameterValue


@dataclass
class SetParametersResult(IdlStruct, typename=MSG + "SetParametersResult_"):
    successful: bool
    reason: str


@dataclass
class FloatingPointRange(IdlStruct, typename=MSG + "FloatingPointRange_"):
    from_value: t.float64
    to_value: t.float64
    step: t.float64


@dataclass
class IntegerRange(IdlStruct, typename=MSG + "IntegerRange_"):
    from_value: t.int64
    to_value: t.int64
    step: t.uint64


@dataclass
class ParameterDescriptor(IdlStruct, typename=MSG + "ParameterDescriptor_"):
    name: str
    type: t.uint8
    description: str
    additional_constraints: str
    read_only: bool
    dynamic_typing: bool
    floating_point_range: t.sequence[FloatingPointRange, 1]
    integer_range: t.sequence[IntegerRange, 1]


@dataclass
class ParameterEvent(IdlStruct, typename=MSG + "ParameterEvent_"):
    stamp: Time
    node: str
    new_parameters: t.sequence[Parameter]
    changed_parameters: t.sequence[Parameter]
    deleted_parameters: t.sequence[Parameter]


@dataclass
class Log(IdlStruct, typename=MSG + "Log_"):
    stamp: Time
    level: t.uint8
    name: str
    msg: str
    file: str
    function: str
    line: t.uint32


# Requests and replies: rmw_cyclonedds's header (client id, sequence number) first.
@dataclass
class GetRequest(IdlStruct, typename=SRV + "GetParameters_Request_"):
    client: t.uint64
    seq: t.int64
    names: t.sequence[str]


@dataclass
class GetResponse(IdlStruct, typename=SRV + "GetParameters_Response_"):
    client: t.uint64
    seq: t.int64
    values: t.sequence[ParameterValue]


@dataclass
class SetRequest(IdlStruct, typename=SRV + "SetParameters_Request_"):
    client: t.uint64
    seq: t.int64
    parameters: t.sequence[Parameter]


@dataclass
class SetResponse(IdlStruct, typename=SRV + "SetParameters_Response_"):
    client: t.uint64
    seq: t.int64
    results: t.sequence[SetParametersResult]


@dataclass
class SetAtomicRequest(IdlStruct, typename=SRV + "SetParametersAtomically_Request_"):
    client: t.uint64
    seq: t.int64
    parameters: t.sequence[Parameter]


@dataclass
class SetAtomicResponse(IdlStruct, typename=SRV + "SetParametersAtomically_Response_"):
    client: t.uint64
    seq: t.int64
    result: SetParametersResult


@dataclass
class DescribeRequest(IdlStruct, typename=SRV + "DescribeParameters_Request_"):
    client: t.uint64
    seq: t.int64
    names: t.sequence[str]


@dataclass
class DescribeResponse(IdlStruct, typename=SRV + "DescribeParameters_Response_"):
    client: t.uint64
    seq: t.int64
    descriptors: t.sequence[ParameterDescriptor]


@dataclass
class ListRequest(IdlStruct, typename=SRV + "ListParameters_Request_"):
    client: t.uint64
    seq: t.int64
    prefixes: t.sequence[str]
    depth: t.uint64


@dataclass
class ListResult(IdlStruct, typename=MSG + "ListParametersResult_"):
    names: t.sequence[str]
    prefixes: t.sequence[str]


@dataclass
class ListResponse(IdlStruct, typename=SRV + "ListParameters_Response_"):
    client: t.uint64
    seq: t.int64
    result: ListResult


CLIENT_ID = 0x5250_4B4D_7065_6572  # "RPKMpeer": any id, echoed by the server


def value_of(v):
    pv = ParameterValue(0, False, 0, 0.0, "", [], [], [], [], [])
    if isinstance(v, bool):
        pv.type, pv.bool_value = 1, v
    elif isinstance(v, int):
        pv.type, pv.integer_value = 2, v
    elif isinstance(v, float):
        pv.type, pv.double_value = 3, v
    elif isinstance(v, str):
        pv.type, pv.string_value = 4, v
    else:
        raise ValueError(f"unsupported value {v!r}")
    return pv


def plain(pv):
    """A ParameterValue as JSON: [type, value]."""
    return [pv.type, {1: pv.bool_value, 2: pv.integer_value, 3: pv.double_value,
                      4: pv.string_value}.get(pv.type)]


class Peer:
    def __init__(self, domain, node, deadline):
        self.dp = DomainParticipant(domain)
        self.domain = domain
        self.node = node
        self.deadline = deadline
        self.seq = 0
        reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                       Policy.History.KeepLast(10))
        latched = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                      Policy.Durability.TransientLocal, Policy.History.KeepLast(100))
        self.services = {}
        for name, req, resp in [("get_parameters", GetRequest, GetResponse),
                                ("set_parameters", SetRequest, SetResponse),
                                ("set_parameters_atomically", SetAtomicRequest, SetAtomicResponse),
                                ("describe_parameters", DescribeRequest, DescribeResponse),
                                ("list_parameters", ListRequest, ListResponse)]:
            rq = Topic(self.dp, f"rq{node}/{name}Request", req)
            rr = Topic(self.dp, f"rr{node}/{name}Reply", resp)
            self.services[name] = (DataWriter(self.dp, rq, qos=reliable),
                                   DataReader(self.dp, rr, qos=reliable))
        self.events = DataReader(self.dp, Topic(self.dp, "rt/parameter_events", ParameterEvent),
                                 qos=latched)
        self.rosout = DataReader(self.dp, Topic(self.dp, "rt/rosout", Log), qos=latched)
        self.seen_events = []
        self.seen_logs = []

    def matched(self, name):
        w, r = self.services[name]
        return bool(w.get_matched_subscriptions()) and bool(r.get_matched_publications())

    def call(self, name, make_request):
        """Sends the request (again every second until a reply: the server's reply writer
        may not have discovered our reader yet) and returns the matching reply."""
        w, r = self.services[name]
        while not self.matched(name):
            if time.monotonic() > self.deadline:
                raise TimeoutError(f"{name}: the service was not discovered")
            time.sleep(0.02)
        self.seq += 1
        seq = self.seq
        while time.monotonic() < self.deadline:
            w.write(make_request(seq))
            resend = time.monotonic() + 1.0
            while time.monotonic() < min(resend, self.deadline):
                for reply in r.take(N=16):
                    if getattr(reply, "client", None) == CLIENT_ID and reply.seq == seq:
                        return reply
                time.sleep(0.005)
        raise TimeoutError(f"{name}: no reply to request {seq}")

    def poll_topics(self):
        for e in self.events.take(N=64):
            if isinstance(e, ParameterEvent) and e.node == self.node:
                self.seen_events.append(e)
        for m in self.rosout.take(N=64):
            if isinstance(m, Log):
                self.seen_logs.append(m)

    def await_event(self, name):
        while time.monotonic() < self.deadline:
            self.poll_topics()
            for e in self.seen_events:
                for p in e.changed_parameters:
                    if p.name == name:
                        return {"node": e.node, "name": p.name, "value": plain(p.value),
                                "stamp": [e.stamp.sec, e.stamp.nanosec]}
            time.sleep(0.01)
        raise TimeoutError(f"no /parameter_events change of {name}")

    def await_rosout(self, text):
        while time.monotonic() < self.deadline:
            self.poll_topics()
            for m in self.seen_logs:
                if text in m.msg:
                    return {"name": m.name, "level": m.level, "msg": m.msg, "file": m.file,
                            "line": m.line}
            time.sleep(0.01)
        raise TimeoutError(f"no /rosout record containing {text!r}")

    def first_calls(self, n, names):
        """N one-shot clients: a reply lost to the race between our reply reader's discovery
        and the server's reply counts as lost (no resend)."""
        reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                       Policy.History.KeepLast(10))
        replied = 0
        for i in range(n):
            client = CLIENT_ID + 1 + i
            dp = DomainParticipant(self.domain)
            rq = Topic(dp, f"rq{self.node}/get_parametersRequest", GetRequest)
            rr = Topic(dp, f"rr{self.node}/get_parametersReply", GetResponse)
            w = DataWriter(dp, rq, qos=reliable)
            r = DataReader(dp, rr, qos=reliable)
            while not (w.get_matched_subscriptions() and r.get_matched_publications()):
                if time.monotonic() > self.deadline:
                    raise TimeoutError(f"first call {i}: the service was not discovered")
                time.sleep(0.001)
            w.write(GetRequest(client, 1, names))
            until = time.monotonic() + 3.0
            got = False
            while not got and time.monotonic() < until:
                got = any(getattr(x, "client", None) == client and x.seq == 1
                          for x in r.take(N=16))
                time.sleep(0.002)
            replied += got
            del w, r, rq, rr, dp
        return [replied, n]

    def step(self, s):
        if "first_calls" in s:
            return {"first_calls": self.first_calls(s["first_calls"], s["get"])}
        if "get" in s:
            reply = self.call("get_parameters", lambda q: GetRequest(CLIENT_ID, q, s["get"]))
            return {"get": dict(zip(s["get"], (plain(v) for v in reply.values)))}
        if "set" in s:
            items = list(s["set"].items())
            params = [Parameter(k, value_of(v)) for k, v in items]
            reply = self.call("set_parameters", lambda q: SetRequest(CLIENT_ID, q, params))
            return {"set": {k: [r.successful, r.reason] for (k, _), r in zip(items, reply.results)}}
        if "set_atomically" in s:
            params = [Parameter(k, value_of(v)) for k, v in s["set_atomically"].items()]
            reply = self.call("set_parameters_atomically",
                              lambda q: SetAtomicRequest(CLIENT_ID, q, params))
            return {"set_atomically": [reply.result.successful, reply.result.reason]}
        if "describe" in s:
            reply = self.call("describe_parameters",
                              lambda q: DescribeRequest(CLIENT_ID, q, s["describe"]))
            out = {}
            for d in reply.descriptors:
                out[d.name] = {
                    "type": d.type, "read_only": d.read_only, "description": d.description,
                    "float_range": [[r.from_value, r.to_value] for r in d.floating_point_range],
                    "integer_range": [[r.from_value, r.to_value] for r in d.integer_range]}
            return {"describe": out}
        if "list" in s:
            reply = self.call("list_parameters", lambda q: ListRequest(CLIENT_ID, q, [], 0))
            return {"list": list(reply.result.names)}
        if "await_event" in s:
            return {"event": self.await_event(s["await_event"])}
        if "await_rosout" in s:
            return {"rosout": self.await_rosout(s["await_rosout"])}
        raise ValueError(f"unknown step {s}")


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("script")
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    p.add_argument("--node", default="/rpkm/preload_monitor")
    p.add_argument("--timeout", type=float, default=30.0)
    args = p.parse_args()
    with open(args.script) as f:
        script = json.load(f)
    peer = Peer(args.domain, args.node, time.monotonic() + args.timeout)
    try:
        for s in script:
            print(json.dumps(peer.step(s)), flush=True)
    except TimeoutError as e:
        print(json.dumps({"timeout": str(e)}), flush=True)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

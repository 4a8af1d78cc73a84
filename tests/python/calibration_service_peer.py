#!/usr/bin/env python3
"""Independent client of rpkm's `~/load_calibration` and `~/save_calibration` (Eclipse
Cyclone DDS, PyPI `cyclonedds`), as `ros2 service call` on rmw_cyclonedds speaks to them:
topics `rq<node>/<service>Request` and `rr<node>/<service>Reply`, types
`rpkm_msgs::srv::dds_::LoadCalibration_Request_` / `_Response_` (SaveCalibration alike, the
fields of msgs/srv/*.srv), rmw_cyclonedds's 16-byte header (client id, sequence number)
first.

  calibration_service_peer.py --domain D --node /rpkm/tcp_estimator \
      --service load_calibration --path FILE --timeout S

Prints one JSON line {"success": bool, "message": str}; exit 0, or 2 on a timeout.
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

SRV = "rpkm_msgs::srv::dds_::"
CLIENT_ID = 0x5250_4B4D_6361_6C31  # "RPKMcal1": any id, echoed by the server


def types(kind):
    @dataclass
    class Request(IdlStruct, typename=f"{SRV}{kind}_Request_"):
        client: t.uint64
        seq: t.int64
        path: str

    @dataclass
    class Response(IdlStruct, typename=f"{SRV}{kind}_Response_"):
        client: t.uint64
        seq: t.int64
        success: bool
        message: str

    return Request, Response


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--node", required=True)
    ap.add_argument("--service", choices=["load_calibration", "save_calibration"], required=True)
    ap.add_argument("--path", required=True)
    ap.add_argument("--timeout", type=float, default=30.0)
    a = ap.parse_args()
    kind = {"load_calibration": "LoadCalibration", "save_calibration": "SaveCalibration"}[a.service]
    Request, Response = types(kind)
    deadline = time.monotonic() + a.timeout
    dp = DomainParticipant(a.domain)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    w = DataWriter(dp, Topic(dp, f"rq{a.node}/{a.service}Request", Request), qos=qos)
    r = DataReader(dp, Topic(dp, f"rr{a.node}/{a.service}Reply", Response), qos=qos)
    while not (w.get_matched_subscriptions() and r.get_matched_publications()):
        if time.monotonic() > deadline:
            print(json.dumps({"error": "service not discovered"}))
            sys.exit(2)
        time.sleep(0.02)
    # one request, sent again every second until its reply (the reply writer may not have
    # matched our reader yet); the server answers each, the first reply is taken
    while time.monotonic() < deadline:
        w.write(Request(CLIENT_ID, 1, a.path))
        resend = time.monotonic() + 1.0
        while time.monotonic() < min(resend, deadline):
            for reply in r.take(N=16):
                if getattr(reply, "client", None) == CLIENT_ID and reply.seq == 1:
                    print(json.dumps({"success": reply.success, "message": reply.message}))
                    return
            time.sleep(0.005)
    print(json.dumps({"error": "no reply"}))
    sys.exit(2)


if __name__ == "__main__":
    main()

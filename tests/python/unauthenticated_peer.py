#!/usr/bin/env python3
"""A Cyclone DDS participant without credentials on the domain of a secured rpkm node set
(tests/it/security_cell.rs): what can it see and do?

  unauthenticated_peer.py --domain D --seconds S --node /rpkm/tcp_estimator [--until FILE]

For S seconds (or until FILE exists) it subscribes to /rpkm/tcp_estimate and asks NODE's get_parameters service
once a second, as `ros2 param get` does (ros2_params_peer.py's types). Then it prints one
JSON line: {"estimate_writers": n, "parameter_endpoints": n, "samples": n, "answers": n,
"requests": n}: the rpkm endpoints its own matched (a writer of estimates; the service's
request reader and reply writer), the estimates and the answers it got. With SROS2 on the
rpkm side all but `requests` must be 0. (The builtin discovery topics are not read: their
readers crash the PyPI cyclonedds 11.0.1 binding here.)
"""

import argparse
import json
import os
import sys
import time

import loopback  # noqa: E402,F401  (before cyclonedds: the loopback configuration)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from cyclone_peer import TcpEstimate  # noqa: E402
from ros2_params_peer import CLIENT_ID, GetRequest, GetResponse  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--domain", type=int, required=True)
    p.add_argument("--seconds", type=float, required=True)
    p.add_argument("--node", required=True)
    p.add_argument("--until", help="stop as soon as this file exists")
    a = p.parse_args()

    dp = DomainParticipant(a.domain)
    reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(64))
    estimates = DataReader(dp, Topic(dp, "rt/rpkm/tcp_estimate", TcpEstimate), qos=reliable)
    rq = DataWriter(dp, Topic(dp, f"rq{a.node}/get_parametersRequest", GetRequest), qos=reliable)
    rr = DataReader(dp, Topic(dp, f"rr{a.node}/get_parametersReply", GetResponse), qos=reliable)
    print(f"unauthenticated peer on domain {a.domain}", file=sys.stderr, flush=True)

    writers, servers, samples, answers = set(), set(), 0, 0
    end = time.monotonic() + a.seconds
    next_request, seq = 0.0, 0
    while time.monotonic() < end and not (a.until and os.path.exists(a.until)):
        writers.update(str(h) for h in estimates.get_matched_publications())
        servers.update(str(h) for h in rq.get_matched_subscriptions())
        servers.update(str(h) for h in rr.get_matched_publications())
        samples += sum(1 for s in estimates.take(N=256) if isinstance(s, TcpEstimate))
        answers += sum(1 for s in rr.take(N=16) if isinstance(s, GetResponse))
        if time.monotonic() >= next_request:
            seq += 1
            rq.write(GetRequest(CLIENT_ID, seq, ["model"]))
            next_request = time.monotonic() + 1.0
        time.sleep(0.02)
    print(json.dumps({"estimate_writers": len(writers), "parameter_endpoints": len(servers),
                      "samples": samples, "answers": answers, "requests": seq}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

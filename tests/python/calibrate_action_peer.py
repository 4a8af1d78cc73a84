#!/usr/bin/env python3
"""Independent action client (Eclipse Cyclone DDS, PyPI `cyclonedds`) of the calibrator's
`~/calibrate`, as rclcpp's and rclpy's action clients on rmw_cyclonedds speak to an action
server: the services `~/calibrate/_action/send_goal`, `get_result`, `cancel_goal` (types
`rpkm_msgs::action::dds_::Calibrate_SendGoal_Request_` / `_Response_`,
`Calibrate_GetResult_...`, `action_msgs::srv::dds_::CancelGoal_...`, rmw_cyclonedds's 16-byte
header first) and the topics `_action/feedback` (`Calibrate_FeedbackMessage_`) and
`_action/status` (`action_msgs::msg::dds_::GoalStatusArray_`), written from
msgs/action/Calibrate.action and ROS 2's action_msgs and unique_identifier_msgs.

  calibrate_action_peer.py --domain D --node /rpkm/calibrator --campaign CSV \
      --validation CSV --cancel-campaign CSV --timeout S

Four goals in turn, then `~/get_state` of the node:
1. the campaign with the validation campaign: every feedback and the result;
2. the cancel campaign (one whose iterations take longer than a cancel's round trip),
   cancelled at its first iteration feedback (cancel by goal id): its result;
3. the campaign with the stated noise and no diagnosis: its result;
4. the cancel campaign again: at its diagnosis feedback `~/get_state` is asked, and once
   answered (while the goal runs) the goal is cancelled: its result and that answer.
Prints one JSON object: per goal "accepted", "status" (the result's: 4 succeeded, 5 canceled,
6 aborted), "result" (its fields; parameter values as given, NaN as null), "feedback" (phase, round, step,
iteration, cost of each), "noise_feedback" (the levels of each noise round), "statuses" (the goal's states seen on the status topic, in order);
for goals 2 and 4 "cancel" (return code, goals canceling, feedback messages before the cancel was
sent, ms from sending it to the result); "state" (the node's lifecycle state id after).
Exit 0, or 2 on a timeout.
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

from cyclone_peer import Time  # noqa: E402
from lifecycle_peer import GetStateRequest, GetStateResponse  # noqa: E402

ACT = "rpkm_msgs::action::dds_::"
CLIENT_ID = 0x5250_4B4D_6163_7431  # "RPKMact1": any id, echoed by the server
PHASE_ITERATION = 1
PHASE_DIAGNOSIS = 3


@dataclass
class UUID(IdlStruct, typename="unique_identifier_msgs::msg::dds_::UUID_"):
    uuid: t.array[t.uint8, 16]


@dataclass
class GoalInfo(IdlStruct, typename="action_msgs::msg::dds_::GoalInfo_"):
    goal_id: UUID
    stamp: Time


@dataclass
class GoalStatus(IdlStruct, typename="action_msgs::msg::dds_::GoalStatus_"):
    goal_info: GoalInfo
    status: t.int8


@dataclass
class GoalStatusArray(IdlStruct, typename="action_msgs::msg::dds_::GoalStatusArray_"):
    status_list: t.sequence[GoalStatus]


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
class Goal(IdlStruct, typename=ACT + "Calibrate_Goal_"):
    campaign_file: str
    validation_file: str
    selection: str
    effects: str
    noise: t.uint8
    skip_diagnosis: bool


@dataclass
class Result(IdlStruct, typename=ACT + "Calibrate_Result_"):
    parameters: Parameters
    val_rms: t.float64
    iterations: t.uint32
    noise_rounds: t.uint32
    noise_groups: t.sequence[str]
    noise_stated: t.sequence[t.float64]
    noise_estimated: t.sequence[t.float64]
    verdict: str
    message: str


@dataclass
class Feedback(IdlStruct, typename=ACT + "Calibrate_Feedback_"):
    phase: t.uint8
    round: t.uint32
    step: t.uint8
    iteration: t.uint32
    cost: t.float64
    noise_groups: t.sequence[str]
    noise_estimated: t.sequence[t.float64]


@dataclass
class FeedbackMessage(IdlStruct, typename=ACT + "Calibrate_FeedbackMessage_"):
    goal_id: UUID
    feedback: Feedback


@dataclass
class SendGoalRequest(IdlStruct, typename=ACT + "Calibrate_SendGoal_Request_"):
    client: t.uint64
    seq: t.int64
    goal_id: UUID
    goal: Goal


@dataclass
class SendGoalResponse(IdlStruct, typename=ACT + "Calibrate_SendGoal_Response_"):
    client: t.uint64
    seq: t.int64
    accepted: bool
    stamp: Time


@dataclass
class GetResultRequest(IdlStruct, typename=ACT + "Calibrate_GetResult_Request_"):
    client: t.uint64
    seq: t.int64
    goal_id: UUID


@dataclass
class GetResultResponse(IdlStruct, typename=ACT + "Calibrate_GetResult_Response_"):
    client: t.uint64
    seq: t.int64
    status: t.int8
    result: Result


@dataclass
class CancelGoalRequest(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Request_"):
    client: t.uint64
    seq: t.int64
    goal_info: GoalInfo


@dataclass
class CancelGoalResponse(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Response_"):
    client: t.uint64
    seq: t.int64
    return_code: t.int8
    goals_canceling: t.sequence[GoalInfo]


def finite(x):
    """A float for JSON: NaN (no value) as null."""
    return None if x != x else x


class Peer:
    def __init__(self, domain, node, deadline):
        self.dp = DomainParticipant(domain)
        self.deadline = deadline
        self.seq = 0
        reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                       Policy.History.KeepLast(10))
        base = f"{node}/calibrate/_action"
        self.services = {}
        for name, req, resp in [("send_goal", SendGoalRequest, SendGoalResponse),
                                ("get_result", GetResultRequest, GetResultResponse),
                                ("cancel_goal", CancelGoalRequest, CancelGoalResponse)]:
            rq = Topic(self.dp, f"rq{base}/{name}Request", req)
            rr = Topic(self.dp, f"rr{base}/{name}Reply", resp)
            self.services[name] = (DataWriter(self.dp, rq, qos=reliable),
                                   DataReader(self.dp, rr, qos=reliable))
        deep = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000))
        self.feedback = DataReader(self.dp, Topic(self.dp, f"rt{base}/feedback", FeedbackMessage),
                                   qos=deep)
        status_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                         Policy.Durability.TransientLocal, Policy.History.KeepLast(100))
        self.status = DataReader(self.dp, Topic(self.dp, f"rt{base}/status", GoalStatusArray),
                                 qos=status_qos)
        get_state = (Topic(self.dp, f"rq{node}/get_stateRequest", GetStateRequest),
                     Topic(self.dp, f"rr{node}/get_stateReply", GetStateResponse))
        self.services["get_state"] = (DataWriter(self.dp, get_state[0], qos=reliable),
                                      DataReader(self.dp, get_state[1], qos=reliable))
        self.heard = {}  # goal id bytes -> [feedback dicts]
        self.statuses = {}  # goal id bytes -> [status, ...] as they changed
        self.pending = {}  # (service, seq) -> reply

    def poll(self):
        for m in self.feedback.take(N=1000):
            if isinstance(m, FeedbackMessage):
                f = m.feedback
                self.heard.setdefault(bytes(m.goal_id.uuid), []).append({
                    "phase": f.phase, "round": f.round, "step": f.step,
                    "iteration": f.iteration, "cost": f.cost,
                    "noise": dict(zip(f.noise_groups, f.noise_estimated))})
        for a in self.status.take(N=100):
            if isinstance(a, GoalStatusArray):
                for s in a.status_list:
                    seen = self.statuses.setdefault(bytes(s.goal_info.goal_id.uuid), [])
                    if not seen or seen[-1] != s.status:
                        seen.append(s.status)
        for name, (_, r) in self.services.items():
            for reply in r.take(N=16):
                if getattr(reply, "client", None) == CLIENT_ID:
                    self.pending[(name, reply.seq)] = reply

    def wait_matched(self):
        for name, (w, r) in self.services.items():
            while not (w.get_matched_subscriptions() and r.get_matched_publications()):
                self.check_deadline(f"{name}: the service was not discovered")
                time.sleep(0.02)
        while not (self.feedback.get_matched_publications() and
                   self.status.get_matched_publications()):
            self.check_deadline("the feedback and status topics were not discovered")
            time.sleep(0.02)

    def check_deadline(self, what):
        if time.monotonic() > self.deadline:
            raise TimeoutError(what)

    def send(self, name, make_request):
        """Writes one request; its sequence number."""
        self.seq += 1
        self.services[name][0].write(make_request(self.seq))
        return self.seq

    def reply(self, name, seq, on_poll=None):
        while (name, seq) not in self.pending:
            self.check_deadline(f"{name}: no reply to request {seq}")
            self.poll()
            if on_poll:
                on_poll()
            time.sleep(0.002)
        return self.pending.pop((name, seq))

    def goal(self, goal, cancel_at_phase=None, ask_state_first=False):
        goal_id = UUID(list(os.urandom(16)))
        key = bytes(goal_id.uuid)
        seq = self.send("send_goal", lambda q: SendGoalRequest(CLIENT_ID, q, goal_id, goal))
        accepted = self.reply("send_goal", seq).accepted
        out = {"accepted": accepted}
        if not accepted:
            return out
        result_seq = self.send("get_result", lambda q: GetResultRequest(CLIENT_ID, q, goal_id))
        cancel = {}

        def maybe_cancel():
            if cancel_at_phase is None or "seq" in cancel:
                return
            its = [f for f in self.heard.get(key, []) if f["phase"] == cancel_at_phase]
            if its and ask_state_first:
                # the node's lifecycle state, asked while the goal runs: the cancel waits
                # for its answer
                if "state_seq" not in cancel:
                    cancel["state_sent"] = time.monotonic()
                    cancel["state_seq"] = self.send(
                        "get_state", lambda q: GetStateRequest(CLIENT_ID, q, 0))
                    return
                answer = self.pending.pop(("get_state", cancel["state_seq"]), None)
                if answer is None:
                    return
                cancel["state_during"] = {
                    "id": answer.current_state.id,
                    "ms": (time.monotonic() - cancel["state_sent"]) * 1e3,
                }
            if its and (not ask_state_first or "state_during" in cancel):
                cancel["before"] = len(self.heard[key])
                cancel["sent"] = time.monotonic()
                cancel["seq"] = self.send("cancel_goal", lambda q: CancelGoalRequest(
                    CLIENT_ID, q, GoalInfo(goal_id, Time(0, 0))))

        reply = self.reply("get_result", result_seq, maybe_cancel)
        done = time.monotonic()
        # the feedback and status writers are not the reply's: let them finish arriving
        end = done + 1.0
        while time.monotonic() < end:
            self.poll()
            time.sleep(0.01)
        r = reply.result
        out.update({
            "status": reply.status,
            "result": {
                "val_rms": finite(r.val_rms), "iterations": r.iterations,
                "noise_rounds": r.noise_rounds, "verdict": r.verdict, "message": r.message,
                "noise": {g: [s, e] for g, s, e in zip(r.noise_groups, r.noise_stated,
                                                       r.noise_estimated)},
                "parameters": dict(zip(r.parameters.names, r.parameters.values)),
                "model": r.parameters.model,
                "measurement_count": r.parameters.measurement_count,
                "param_val_rms": finite(r.parameters.val_rms),
            },
            "feedback": [{k: f[k] for k in ("phase", "round", "step", "iteration", "cost")}
                         for f in self.heard.get(key, [])],
            "noise_feedback": [f["noise"] for f in self.heard.get(key, []) if f["phase"] == 2],
            "statuses": self.statuses.get(key, []),
        })
        if "seq" in cancel:
            answer = self.reply("cancel_goal", cancel["seq"])
            out["cancel"] = {
                "return_code": answer.return_code,
                "goals_canceling": [bytes(g.goal_id.uuid) == key for g in answer.goals_canceling],
                "feedback_before": cancel["before"],
                "ms_to_result": (done - cancel["sent"]) * 1e3,
                "state_during": cancel.get("state_during"),
            }
        return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--node", required=True)
    ap.add_argument("--campaign", required=True)
    ap.add_argument("--validation", required=True)
    ap.add_argument("--cancel-campaign", required=True)
    ap.add_argument("--timeout", type=float, default=120.0)
    a = ap.parse_args()
    peer = Peer(a.domain, a.node, time.monotonic() + a.timeout)
    peer.wait_matched()
    full = Goal(a.campaign, a.validation, "", "", 1, False)
    out = {"goals": [
        peer.goal(full),
        peer.goal(Goal(a.cancel_campaign, "", "", "", 1, False), cancel_at_phase=PHASE_ITERATION),
        peer.goal(Goal(a.campaign, "", "map", "", 2, True)),
        peer.goal(Goal(a.cancel_campaign, "", "", "", 1, False), cancel_at_phase=PHASE_DIAGNOSIS,
                  ask_state_first=True),
    ]}
    seq = peer.send("get_state", lambda q: GetStateRequest(CLIENT_ID, q, 0))
    out["state"] = peer.reply("get_state", seq).current_state.id
    print(json.dumps(out))


if __name__ == "__main__":
    try:
        main()
    except TimeoutError as e:
        print(json.dumps({"error": str(e)}))
        sys.exit(2)

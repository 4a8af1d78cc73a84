// A ROS 2 service and action client on eProsima Fast DDS (Debian's libfastrtps) made as
// rmw_fastrtps makes its clients (rmw_fastrtps_shared_cpp, Humble and Jazzy alike), types
// from fastddsgen (fastdds_rpc.idl), to call rpkm's nodes as `ros2 param`, `ros2 lifecycle`
// and `ros2 action send_goal` on ROS 2's default middleware do:
//
// - a service is the topics rq<service>Request and rr<service>Reply, types
//   pkg::srv::dds_::X_Request_ / _Response_, reliable, volatile, keep last 10 (ROS 2's
//   services profile); no request id in the payload;
// - the request is written with WriteParams whose related_sample_identity's writer GUID is the
//   client's reply reader's GUID (rmw_request.cpp, __rmw_send_request), its sequence number is
//   the one the writer gave the sample (the request id);
// - a reply is the client's when its related_sample_identity's writer GUID is the reply
//   reader's or the request writer's and its sequence number the request's
//   (rmw_response.cpp, __rmw_take_response); any other reply on the topic is ignored (counted);
// - before its first call a client waits for its request writer and reply reader to be
//   matched, as many of one as of the other (rmw_service_server_is_available.cpp);
// - an action is the services <action>/_action/send_goal, cancel_goal, get_result and the
//   topics <action>/_action/feedback (reliable, volatile) and _action/status (reliable,
//   transient local, keep last 1); the client takes the feedback of its goal id.
//
//   fastdds_rpc_peer DOMAIN SCRIPT CALL_TIMEOUT_S [ENCLAVE_DIR]
//
// SCRIPT lines (NODE a full node name, /rpkm/ingest):
//   list NODE                      -> LIST NODE NAME,NAME,...
//   get NODE NAME                  -> GET NODE NAME TYPE VALUE
//   set NODE NAME TYPE VALUE       -> SET NODE NAME ok | SET NODE NAME refused: REASON
//                                     (TYPE bool|integer|double|string; VALUE '' is empty)
//   state NODE                     -> STATE NODE ID LABEL
//   change NODE TRANSITION_ID      -> CHANGE NODE ID true|false
//   calibrate NODE CAMPAIGN VALIDATION|- NOISE SKIP_DIAGNOSIS(0|1)
//       -> GOAL accepted|refused, then FEEDBACK PHASE ROUND STEP ITERATION COST per feedback,
//          STATUS S per status change of the goal, PARAM NAME VALUE per parameter,
//          RESULT STATUS ITERATIONS NOISE_ROUNDS VAL_RMS VERDICT|- and MESSAGE TEXT
// A call not answered within CALL_TIMEOUT_S prints NOREPLY CMD NODE (UNAVAILABLE CMD NODE
// (request writer matched N, reply reader matched M): the service was not matched, N and M the
// remote endpoints each had matched) and ends the script (the calls after it build on it).
// Ends with DONE CALLS REPLIES IGNORED (replies on the topics that were not its own). Exit 0 when every
// call was answered, 2 when not, 3 when the participant cannot be created, 64 on bad usage or
// a bad script line.
//
//   fastdds_rpc_peer --serve DOMAIN NODE SECONDS
//
// The check of the client: a server answering `NODE/get_state` (3 active), `NODE/change_state`
// (success when the transition is 3) and `NODE/list_parameters` (the names `check`, `rpc`) as
// rmw_fastrtps's server does (rmw_request.cpp __rmw_take_request, rmw_response.cpp
// __rmw_send_response): the reply's related_sample_identity is the request's related writer GUID
// when given (the reply reader's; the server waits for its reply writer to match that reader)
// else the request writer's, with the request's sequence number. Before each true reply it
// writes two decoys that a correct client ignores: the request's sequence number + 1000, and
// another GUID. Prints SERVED N at the end.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/common/InstanceHandle.h>
#include <fastdds/rtps/common/WriteParams.h>

#include "fastdds_participant.hpp"
#include "fastdds_rpc.h"
#include "fastdds_rpcPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::GUID_t;
using eprosima::fastrtps::rtps::SequenceNumber_t;
using eprosima::fastrtps::rtps::WriteParams;
using Clock = std::chrono::steady_clock;
namespace rcl = rcl_interfaces::msg::dds_;
namespace rcls = rcl_interfaces::srv::dds_;
namespace lc = lifecycle_msgs::srv::dds_;
namespace am = action_msgs::msg::dds_;
namespace cal = rpkm_msgs::action::dds_;

namespace {

std::vector<std::string> words(const std::string &line) {
  std::vector<std::string> out;
  std::stringstream in(line);
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

std::string joined(const std::vector<std::string> &items) {
  if (items.empty()) return "-";
  std::string out;
  for (const auto &s : items) out += (out.empty() ? "" : ",") + s;
  return out;
}

std::string guid_text(const GUID_t &g) {
  std::ostringstream s;
  s << g;
  return s.str();
}

// Endpoints of the peer's one participant; topics by name, made once.
struct Dds {
  DomainParticipant *participant = nullptr;
  Publisher *publisher = nullptr;
  Subscriber *subscriber = nullptr;
  std::map<std::string, Topic *> topics;

  Topic *topic(const std::string &name, const std::string &type) {
    auto it = topics.find(name);
    if (it != topics.end()) return it->second;
    Topic *t = participant->create_topic(name, type, TOPIC_QOS_DEFAULT);
    topics[name] = t;
    return t;
  }

  // ROS 2's services profile (and the topics' default): reliable, volatile, keep last 10;
  // rmw_fastrtps's own settings: preallocated with realloc, no data sharing.
  DataWriterQos writer_qos(int depth = 10) const {
    DataWriterQos q = publisher->get_default_datawriter_qos();
    q.reliability().kind = RELIABLE_RELIABILITY_QOS;
    q.durability().kind = VOLATILE_DURABILITY_QOS;
    q.history().kind = KEEP_LAST_HISTORY_QOS;
    q.history().depth = depth;
    q.endpoint().history_memory_policy =
        eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    q.data_sharing().off();
    return q;
  }

  DataReaderQos reader_qos(int depth = 10) const {
    DataReaderQos q = subscriber->get_default_datareader_qos();
    q.reliability().kind = RELIABLE_RELIABILITY_QOS;
    q.durability().kind = VOLATILE_DURABILITY_QOS;
    q.history().kind = KEEP_LAST_HISTORY_QOS;
    q.history().depth = depth;
    q.endpoint().history_memory_policy =
        eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    q.data_sharing().off();
    return q;
  }
};

int publication_matches(DataWriter *w) {
  PublicationMatchedStatus s;
  w->get_publication_matched_status(s);
  return s.current_count;
}

int subscription_matches(DataReader *r) {
  SubscriptionMatchedStatus s;
  r->get_subscription_matched_status(s);
  return s.current_count;
}

// One service client: the request writer and the reply reader of `<service>`.
struct Client {
  DataWriter *writer = nullptr;
  DataReader *reader = nullptr;
  GUID_t writer_guid;
  GUID_t reader_guid;

  Client(Dds &dds, const std::string &service, const std::string &type) {
    Topic *rq = dds.topic("rq" + service + "Request", type + "_Request_");
    Topic *rr = dds.topic("rr" + service + "Reply", type + "_Response_");
    reader = dds.subscriber->create_datareader(rr, dds.reader_qos());
    writer = dds.publisher->create_datawriter(rq, dds.writer_qos());
    if (reader != nullptr && writer != nullptr) {
      writer_guid = writer->guid();
      reader_guid = reader->guid();
    }
  }

  // rcl's service_is_available on rmw_fastrtps: both matched, as many of one as of the other.
  bool available() const {
    int w = publication_matches(writer);
    int r = subscription_matches(reader);
    return w > 0 && r > 0 && w == r;
  }

  bool wait_available(Clock::time_point deadline) const {
    while (!available()) {
      if (Clock::now() > deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return true;
  }

  // Writes the request as __rmw_send_request does; its sequence number (the request id).
  template <class Req>
  SequenceNumber_t send(Req &request) {
    WriteParams params;
    params.related_sample_identity().writer_guid() = reader_guid;
    if (!writer->write(&request, params)) return SequenceNumber_t::unknown();
    return params.sample_identity().sequence_number();
  }

  // Takes replies until the one whose related sample identity is (this client, `seq`), as
  // __rmw_take_response accepts it; the others are counted in `ignored`. `idle` runs between
  // polls (an action client reads its feedback meanwhile).
  template <class Resp, class Idle>
  bool reply(const SequenceNumber_t &seq, Resp &out, Clock::time_point deadline, long &ignored,
             Idle idle) {
    while (Clock::now() < deadline) {
      SampleInfo info;
      Resp r;
      while (reader->take_next_sample(&r, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;
        const auto &related = info.related_sample_identity;
        bool ours = related.writer_guid() == reader_guid || related.writer_guid() == writer_guid;
        if (ours && related.sequence_number() == seq) {
          out = r;
          return true;
        }
        ignored++;
      }
      idle();
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return false;
  }
};

std::string value_text(const rcl::ParameterValue_ &v) {
  std::ostringstream s;
  switch (v.type()) {
    case 1: s << (v.bool_value() ? "true" : "false"); break;
    case 2: s << v.integer_value(); break;
    case 3: {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.17g", v.double_value());
      s << buf;
      break;
    }
    case 4: s << (v.string_value().empty() ? "''" : v.string_value()); break;
    case 9: s << joined(v.string_array_value()); break;
    default: s << "-";
  }
  return s.str();
}

// Reads `TYPE VALUE` as a parameter value; false for a type it does not know.
bool parse_value(const std::string &type, const std::string &text, rcl::ParameterValue_ &v) {
  std::string value = text == "''" ? "" : text;
  if (type == "bool") {
    v.type(1);
    v.bool_value(value == "true");
  } else if (type == "integer") {
    v.type(2);
    v.integer_value(std::atoll(value.c_str()));
  } else if (type == "double") {
    v.type(3);
    v.double_value(std::strtod(value.c_str(), nullptr));
  } else if (type == "string") {
    v.type(4);
    v.string_value(value);
  } else {
    return false;
  }
  return true;
}

// The client side: one Client per service, made at its first call.
struct Peer {
  Dds dds;
  double call_timeout_s = 10;
  std::map<std::string, Client *> clients;
  long calls = 0;
  long replies = 0;
  long ignored = 0;

  Clock::time_point deadline() const {
    return Clock::now() + std::chrono::duration_cast<Clock::duration>(
                              std::chrono::duration<double>(call_timeout_s));
  }

  Client *client(const std::string &service, const std::string &type) {
    auto it = clients.find(service);
    if (it != clients.end()) return it->second;
    auto *c = new Client(dds, service, type);
    clients[service] = c;
    return c;
  }

  // One call of `service`: false (and a NOREPLY or UNAVAILABLE line) when not answered.
  template <class Req, class Resp, class Idle>
  bool call(const std::string &what, const std::string &service, const std::string &type,
            Req &request, Resp &response, Idle idle) {
    calls++;
    Client *c = client(service, type);
    auto until = deadline();
    if (!c->wait_available(until)) {
      std::printf("UNAVAILABLE %s (request writer matched %d, reply reader matched %d)\n",
                  what.c_str(), publication_matches(c->writer), subscription_matches(c->reader));
      return false;
    }
    SequenceNumber_t seq = c->send(request);
    if (!c->reply(seq, response, until, ignored, idle)) {
      std::printf("NOREPLY %s\n", what.c_str());
      return false;
    }
    replies++;
    return true;
  }

  template <class Req, class Resp>
  bool call(const std::string &what, const std::string &service, const std::string &type,
            Req &request, Resp &response) {
    return call(what, service, type, request, response, [] {});
  }

  bool list(const std::string &node) {
    rcls::ListParameters_Request_ rq;
    rcls::ListParameters_Response_ rs;
    if (!call("list " + node, node + "/list_parameters", "rcl_interfaces::srv::dds_::ListParameters",
              rq, rs))
      return false;
    std::printf("LIST %s %s\n", node.c_str(), joined(rs.result().names()).c_str());
    return true;
  }

  bool get(const std::string &node, const std::string &name) {
    rcls::GetParameters_Request_ rq;
    rq.names({name});
    rcls::GetParameters_Response_ rs;
    if (!call("get " + node, node + "/get_parameters", "rcl_interfaces::srv::dds_::GetParameters",
              rq, rs))
      return false;
    for (const auto &v : rs.values()) {
      std::printf("GET %s %s %u %s\n", node.c_str(), name.c_str(), (unsigned)v.type(),
                  value_text(v).c_str());
    }
    return true;
  }

  bool set(const std::string &node, const std::string &name, const rcl::ParameterValue_ &v) {
    rcls::SetParameters_Request_ rq;
    rcl::Parameter_ p;
    p.name(name);
    p.value(v);
    rq.parameters({p});
    rcls::SetParameters_Response_ rs;
    if (!call("set " + node, node + "/set_parameters", "rcl_interfaces::srv::dds_::SetParameters",
              rq, rs))
      return false;
    for (const auto &r : rs.results()) {
      if (r.successful()) {
        std::printf("SET %s %s ok\n", node.c_str(), name.c_str());
      } else {
        std::printf("SET %s %s refused: %s\n", node.c_str(), name.c_str(), r.reason().c_str());
      }
    }
    return true;
  }

  bool state(const std::string &node) {
    lc::GetState_Request_ rq;
    lc::GetState_Response_ rs;
    if (!call("state " + node, node + "/get_state", "lifecycle_msgs::srv::dds_::GetState", rq, rs))
      return false;
    std::printf("STATE %s %u %s\n", node.c_str(), (unsigned)rs.current_state().id(),
                rs.current_state().label().c_str());
    return true;
  }

  bool change(const std::string &node, int id) {
    lc::ChangeState_Request_ rq;
    rq.transition().id((uint8_t)id);
    lc::ChangeState_Response_ rs;
    if (!call("change " + node, node + "/change_state", "lifecycle_msgs::srv::dds_::ChangeState",
              rq, rs))
      return false;
    std::printf("CHANGE %s %d %s\n", node.c_str(), id, rs.success() ? "true" : "false");
    return true;
  }

  bool calibrate(const std::string &node, const std::vector<std::string> &f);
};

// The action's topics, read as rcl_action's client reads them: feedback of its goal, the
// goal's status changes.
struct ActionTopics {
  DataReader *feedback = nullptr;
  DataReader *status = nullptr;
  unique_identifier_msgs::msg::dds_::UUID_ goal;
  int last_status = -1;

  ActionTopics(Dds &dds, const std::string &action) {
    // feedback: the default topic profile (reliable, volatile); deeper than its keep last 10
    // so that a slow poll loses none of the feedback the test counts
    feedback = dds.subscriber->create_datareader(
        dds.topic("rt" + action + "/_action/feedback",
                  "rpkm_msgs::action::dds_::Calibrate_FeedbackMessage_"),
        dds.reader_qos(1000));
    DataReaderQos sq = dds.reader_qos(1);
    sq.durability().kind = TRANSIENT_LOCAL_DURABILITY_QOS;
    status = dds.subscriber->create_datareader(
        dds.topic("rt" + action + "/_action/status", "action_msgs::msg::dds_::GoalStatusArray_"),
        sq);
  }

  bool matched() const {
    return subscription_matches(feedback) > 0 && subscription_matches(status) > 0;
  }

  void poll() {
    SampleInfo info;
    cal::Calibrate_FeedbackMessage_ m;
    while (feedback->take_next_sample(&m, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data || m.goal_id().uuid() != goal.uuid()) continue;
      const auto &f = m.feedback();
      std::printf("FEEDBACK %u %u %u %u %.17g\n", (unsigned)f.phase(), f.round(),
                  (unsigned)f.step(), f.iteration(), f.cost());
    }
    am::GoalStatusArray_ a;
    while (status->take_next_sample(&a, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      for (const auto &s : a.status_list()) {
        if (s.goal_info().goal_id().uuid() != goal.uuid() || s.status() == last_status) continue;
        last_status = s.status();
        std::printf("STATUS %d\n", last_status);
      }
    }
  }
};

// A Calibrate goal as rclcpp's action client sends it: send_goal with a random goal id, on
// acceptance get_result; feedback and status read meanwhile.
bool Peer::calibrate(const std::string &node, const std::vector<std::string> &f) {
  std::string action = node + "/calibrate";
  ActionTopics topics(dds, action);
  std::string prefix = action + "/_action/";
  std::string types = "rpkm_msgs::action::dds_::Calibrate_";
  // rcl_action_server_is_available: the three services and the two topics
  auto until = deadline();
  for (const char *s : {"send_goal", "get_result"}) {
    std::string t = std::string(s) == "send_goal" ? "SendGoal" : "GetResult";
    client(prefix + s, types + t);
  }
  client(prefix + "cancel_goal", "action_msgs::srv::dds_::CancelGoal");
  for (const char *s : {"send_goal", "get_result", "cancel_goal"}) {
    if (!clients[prefix + s]->wait_available(until)) {
      std::printf("UNAVAILABLE calibrate %s (%s)\n", node.c_str(), s);
      calls++;
      return false;
    }
  }
  while (!topics.matched() && Clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  std::random_device rd;
  for (auto &b : topics.goal.uuid()) b = (uint8_t)rd();
  cal::Calibrate_SendGoal_Request_ goal;
  goal.goal_id(topics.goal);
  goal.goal().campaign_file(f[2]);
  goal.goal().validation_file(f[3] == "-" ? "" : f[3]);
  goal.goal().noise((uint8_t)std::atoi(f[4].c_str()));
  goal.goal().skip_diagnosis(f[5] == "1");
  cal::Calibrate_SendGoal_Response_ accepted;
  auto poll = [&topics] { topics.poll(); };
  if (!call("calibrate " + node + " send_goal", prefix + "send_goal", types + "SendGoal", goal,
            accepted, poll))
    return false;
  std::printf("GOAL %s\n", accepted.accepted() ? "accepted" : "refused");
  if (!accepted.accepted()) return true;
  cal::Calibrate_GetResult_Request_ ask;
  ask.goal_id(topics.goal);
  cal::Calibrate_GetResult_Response_ result;
  if (!call("calibrate " + node + " get_result", prefix + "get_result", types + "GetResult", ask,
            result, poll))
    return false;
  // the feedback and status writers are not the reply's: what they sent before it, arriving
  auto settle = Clock::now() + std::chrono::milliseconds(500);
  while (Clock::now() < settle) {
    topics.poll();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const auto &r = result.result();
  for (size_t i = 0; i < r.parameters().names().size() && i < r.parameters().values().size(); i++) {
    std::printf("PARAM %s %.17g\n", r.parameters().names()[i].c_str(), r.parameters().values()[i]);
  }
  std::printf("RESULT %d %u %u %.17g %s\n", (int)result.status(), r.iterations(), r.noise_rounds(),
              r.val_rms(), r.verdict().empty() ? "-" : r.verdict().c_str());
  std::printf("MESSAGE %s\n", r.message().c_str());
  return true;
}

// Runs one script line: 0 (answered), 1 (not answered), 64 (a line it cannot run).
int step(Peer &peer, const std::string &line) {
  std::vector<std::string> f = words(line);
  if (f.empty()) return 0;
  bool ok;
  const std::string &cmd = f[0];
  if (cmd == "list" && f.size() == 2) {
    ok = peer.list(f[1]);
  } else if (cmd == "get" && f.size() == 3) {
    ok = peer.get(f[1], f[2]);
  } else if (cmd == "set" && f.size() == 5) {
    rcl::ParameterValue_ v;
    if (!parse_value(f[3], f[4], v)) return 64;
    ok = peer.set(f[1], f[2], v);
  } else if (cmd == "state" && f.size() == 2) {
    ok = peer.state(f[1]);
  } else if (cmd == "change" && f.size() == 3) {
    ok = peer.change(f[1], std::atoi(f[2].c_str()));
  } else if (cmd == "calibrate" && f.size() == 6) {
    ok = peer.calibrate(f[1], f);
  } else {
    return 64;
  }
  std::fflush(stdout);
  return ok ? 0 : 1;
}

// The server side of the check: the reply writer's matched readers, by GUID, as
// rmw_fastrtps's ServicePubListener tracks them.
struct MatchedReaders : DataWriterListener {
  std::mutex mutex;
  std::set<GUID_t> readers;

  void on_publication_matched(DataWriter *, const PublicationMatchedStatus &s) override {
    std::lock_guard<std::mutex> lock(mutex);
    GUID_t g = eprosima::fastrtps::rtps::iHandle2GUID(s.last_subscription_handle);
    if (s.current_count_change > 0) {
      readers.insert(g);
    } else if (s.current_count_change < 0) {
      readers.erase(g);
    }
  }

  bool has(const GUID_t &g) {
    std::lock_guard<std::mutex> lock(mutex);
    return readers.count(g) > 0;
  }
};

struct Server {
  DataReader *requests = nullptr;
  DataWriter *replies = nullptr;
  MatchedReaders matched;

  Server(Dds &dds, const std::string &service, const std::string &type) {
    requests = dds.subscriber->create_datareader(
        dds.topic("rq" + service + "Request", type + "_Request_"), dds.reader_qos());
    replies = dds.publisher->create_datawriter(
        dds.topic("rr" + service + "Reply", type + "_Response_"), dds.writer_qos(), &matched);
  }

  // One request answered with `answer(request)`, as __rmw_take_request and
  // __rmw_send_response do, after the two decoys; whether one was there.
  template <class Req, class Resp, class Answer>
  bool serve(Answer answer, Resp decoy) {
    Req request;
    SampleInfo info;
    if (requests->take_next_sample(&request, &info) != ReturnCode_t::RETCODE_OK ||
        !info.valid_data)
      return false;
    GUID_t related = info.related_sample_identity.writer_guid();
    if (related == GUID_t::unknown()) related = info.sample_identity.writer_guid();
    SequenceNumber_t seq = info.sample_identity.sequence_number();
    constexpr uint8_t entity_id_is_reader_bit = 0x04;
    if ((related.entityId.value[3] & entity_id_is_reader_bit) != 0) {
      auto until = Clock::now() + std::chrono::milliseconds(100);
      while (!matched.has(related) && Clock::now() < until) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
    }
    WriteParams wrong_seq;
    wrong_seq.related_sample_identity().writer_guid() = related;
    wrong_seq.related_sample_identity().sequence_number() = seq + 1000u;
    replies->write(&decoy, wrong_seq);
    WriteParams wrong_guid;
    wrong_guid.related_sample_identity().writer_guid() = replies->guid();
    wrong_guid.related_sample_identity().sequence_number() = seq;
    replies->write(&decoy, wrong_guid);
    Resp reply = answer(request);
    WriteParams params;
    params.related_sample_identity().writer_guid() = related;
    params.related_sample_identity().sequence_number() = seq;
    std::fprintf(stderr, "served request %s #%llu\n", guid_text(related).c_str(),
                 (unsigned long long)seq.to64long());
    return replies->write(&reply, params);
  }
};

int serve(Dds &dds, const std::string &node, double seconds) {
  Server get_state(dds, node + "/get_state", "lifecycle_msgs::srv::dds_::GetState");
  Server change_state(dds, node + "/change_state", "lifecycle_msgs::srv::dds_::ChangeState");
  Server list(dds, node + "/list_parameters", "rcl_interfaces::srv::dds_::ListParameters");
  lc::GetState_Response_ state_decoy;
  state_decoy.current_state().id(99);
  state_decoy.current_state().label("decoy");
  lc::ChangeState_Response_ change_decoy;
  change_decoy.success(false);
  rcls::ListParameters_Response_ list_decoy;
  list_decoy.result().names({"decoy"});
  long served = 0;
  auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(seconds));
  while (Clock::now() < end) {
    bool any = get_state.serve<lc::GetState_Request_>(
        [](const lc::GetState_Request_ &) {
          lc::GetState_Response_ r;
          r.current_state().id(3);
          r.current_state().label("active");
          return r;
        },
        state_decoy);
    any |= change_state.serve<lc::ChangeState_Request_>(
        [](const lc::ChangeState_Request_ &q) {
          lc::ChangeState_Response_ r;
          r.success(q.transition().id() == 3);
          return r;
        },
        change_decoy);
    any |= list.serve<rcls::ListParameters_Request_>(
        [](const rcls::ListParameters_Request_ &) {
          rcls::ListParameters_Response_ r;
          r.result().names({"check", "rpc"});
          return r;
        },
        list_decoy);
    if (any) {
      served++;
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  std::printf("SERVED %ld\n", served);
  return 0;
}

// With FASTDDS_PEER_TRACE set: the participant's discovery as Fast DDS reports it, on stderr
// (`TRACE SECONDS participant|reader|writer STATUS GUID [TOPIC]`, STATUS as Fast DDS numbers
// it: 0 discovered), and Fast DDS's own warnings. A service that stays UNAVAILABLE shows there
// as the remote endpoints Fast DDS never reported (how the missed Fast DDS 2.9 discoveries of
// docs/nodes.md were found).
struct Trace : public DomainParticipantListener {
  Clock::time_point t0 = Clock::now();
  double t() const { return std::chrono::duration<double>(Clock::now() - t0).count(); }
  void on_participant_discovery(DomainParticipant *,
                                eprosima::fastrtps::rtps::ParticipantDiscoveryInfo &&info) override {
    std::fprintf(stderr, "TRACE %.3f participant %d %s\n", t(), int(info.status),
                 guid_text(info.info.m_guid).c_str());
  }
  void on_subscriber_discovery(DomainParticipant *,
                               eprosima::fastrtps::rtps::ReaderDiscoveryInfo &&info) override {
    std::fprintf(stderr, "TRACE %.3f reader %d %s %s\n", t(), int(info.status),
                 guid_text(info.info.guid()).c_str(), info.info.topicName().c_str());
  }
  void on_publisher_discovery(DomainParticipant *,
                              eprosima::fastrtps::rtps::WriterDiscoveryInfo &&info) override {
    std::fprintf(stderr, "TRACE %.3f writer %d %s %s\n", t(), int(info.status),
                 guid_text(info.info.guid()).c_str(), info.info.topicName().c_str());
  }
};

bool make_participant(Dds &dds, int domain, const char *enclave) {
  static Trace trace;
  bool traced = std::getenv("FASTDDS_PEER_TRACE") != nullptr;
  if (traced) {
    eprosima::fastdds::dds::Log::SetVerbosity(eprosima::fastdds::dds::Log::Warning);
  }
  dds.participant = DomainParticipantFactory::get_instance()->create_participant(
      domain, participant_qos("fastdds_rpc_peer", enclave), traced ? &trace : nullptr);
  if (dds.participant == nullptr) return false;
  for (TypeSupport t : {
           TypeSupport(new rcls::ListParameters_Request_PubSubType()),
           TypeSupport(new rcls::ListParameters_Response_PubSubType()),
           TypeSupport(new rcls::GetParameters_Request_PubSubType()),
           TypeSupport(new rcls::GetParameters_Response_PubSubType()),
           TypeSupport(new rcls::SetParameters_Request_PubSubType()),
           TypeSupport(new rcls::SetParameters_Response_PubSubType()),
           TypeSupport(new lc::GetState_Request_PubSubType()),
           TypeSupport(new lc::GetState_Response_PubSubType()),
           TypeSupport(new lc::ChangeState_Request_PubSubType()),
           TypeSupport(new lc::ChangeState_Response_PubSubType()),
           TypeSupport(new cal::Calibrate_SendGoal_Request_PubSubType()),
           TypeSupport(new cal::Calibrate_SendGoal_Response_PubSubType()),
           TypeSupport(new cal::Calibrate_GetResult_Request_PubSubType()),
           TypeSupport(new cal::Calibrate_GetResult_Response_PubSubType()),
           TypeSupport(new cal::Calibrate_FeedbackMessage_PubSubType()),
           TypeSupport(new action_msgs::srv::dds_::CancelGoal_Request_PubSubType()),
           TypeSupport(new action_msgs::srv::dds_::CancelGoal_Response_PubSubType()),
           TypeSupport(new am::GoalStatusArray_PubSubType())}) {
    t.register_type(dds.participant);
  }
  dds.publisher = dds.participant->create_publisher(PUBLISHER_QOS_DEFAULT);
  dds.subscriber = dds.participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  return dds.publisher != nullptr && dds.subscriber != nullptr;
}

}  // namespace

int main(int argc, char **argv) {
  Dds dds;
  if (argc == 5 && std::string(argv[1]) == "--serve") {
    if (!make_participant(dds, std::atoi(argv[2]), nullptr)) return 3;
    return serve(dds, argv[3], std::atof(argv[4]));
  }
  if (argc != 4 && argc != 5) {
    std::fprintf(stderr,
                 "usage: fastdds_rpc_peer DOMAIN SCRIPT CALL_TIMEOUT_S [ENCLAVE_DIR]\n"
                 "       fastdds_rpc_peer --serve DOMAIN NODE SECONDS\n");
    return 64;
  }
  Peer peer;
  peer.call_timeout_s = std::atof(argv[3]);
  if (!make_participant(peer.dds, std::atoi(argv[1]), argc == 5 ? argv[4] : nullptr)) {
    std::fprintf(stderr, "fastdds_rpc_peer: the participant cannot be created\n");
    return 3;
  }
  std::ifstream in(argv[2]);
  if (!in) {
    std::fprintf(stderr, "fastdds_rpc_peer: cannot read %s\n", argv[2]);
    return 64;
  }
  std::string line;
  int code = 0;
  while (std::getline(in, line)) {
    int r = step(peer, line);
    if (r == 64) {
      std::fprintf(stderr, "fastdds_rpc_peer: cannot run %s\n", line.c_str());
      return 64;
    }
    if (r != 0) {
      code = 2;
      break;
    }
  }
  std::printf("DONE %ld %ld %ld\n", peer.calls, peer.replies, peer.ignored);
  std::fflush(stdout);
  // Fast DDS 2.9 with DDS Security crashes (SIGSEGV) tearing down a participant whose
  // endpoints are still in use by its event thread; the calls are done and said, so the peer
  // leaves without running the destructors.
  std::_Exit(code);
}

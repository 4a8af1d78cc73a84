// An independent ros2_control cell and rpkm subscriber on eProsima Fast DDS (Debian's
// libfastrtps, ROS 2's default middleware through rmw_fastrtps), types from fastddsgen
// (fastdds_cell.idl): plays the script of tests/python/joint_states_peer.py (J, T, MATCH,
// WAIT lines; SET is the Cyclone peer's) as /joint_states and thermometer writers, and reads
// /rpkm/tcp_estimate meanwhile, as a ROS 2 node on rmw_fastrtps does (topics rt/..., reliable).
//
//   fastdds_peer DOMAIN SCRIPT|- COUNT TIMEOUT_S [ENCLAVE_DIR]
//
// With ENCLAVE_DIR the participant joins with DDS Security, the files of an SROS2 enclave
// (cert.pem, key.pem, identity_ca.cert.pem, permissions_ca.cert.pem, governance.p7s,
// permissions.p7s) as rmw_fastrtps configures them. SCRIPT `-` plays nothing: the peer only
// listens, until COUNT estimates, the timeout, or the file the environment variable
// FASTDDS_PEER_STOP names exists. MATCH also waits for a writer of the estimates. Prints `E SEQ X Y PSI` per estimate
// (%.17g: exact), then `DONE n JOINT_READERS ESTIMATE_WRITERS` (what it received and matched);
// exit 0 when COUNT estimates arrived, 2 when not (or the cell's readers not matched) by the
// timeout, 3 when the participant cannot be created, 64 on bad usage or a bad script line.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/core/status/PublicationMatchedStatus.hpp>
#include <fastdds/dds/core/status/SubscriptionMatchedStatus.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include "fastdds_cell.h"
#include "fastdds_participant.hpp"
#include "fastdds_cellPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using Clock = std::chrono::steady_clock;
using JointState = sensor_msgs::msg::dds_::JointState_;
using Temperature = sensor_msgs::msg::dds_::Temperature_;
using TcpEstimate = rpkm_msgs::msg::dds_::TcpEstimate_;

namespace {

std::vector<std::string> split(const std::string &s, char sep) {
  std::vector<std::string> out;
  if (s == "-") return out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, sep)) out.push_back(item);
  return out;
}

std::vector<double> numbers(const std::string &s) {
  std::vector<double> out;
  for (const auto &v : split(s, ',')) out.push_back(std::strtod(v.c_str(), nullptr));
  return out;
}

struct Peer {
  DomainParticipant *participant = nullptr;
  Publisher *publisher = nullptr;
  DataWriter *joints = nullptr;
  std::map<std::string, DataWriter *> thermometers;
  DataReader *estimates = nullptr;
  DataWriterQos writer_qos;
  long received = 0;
  Clock::time_point deadline;
  Clock::time_point t0;
  long k = 0;
  long played = 0;

  Topic *topic(const std::string &ros_name, const std::string &type) {
    return participant->create_topic("rt" + ros_name, type, TOPIC_QOS_DEFAULT);
  }

  DataWriter *thermometer(const std::string &ros_name) {
    auto it = thermometers.find(ros_name);
    if (it != thermometers.end()) return it->second;
    DataWriter *w = publisher->create_datawriter(
        topic(ros_name, "sensor_msgs::msg::dds_::Temperature_"), writer_qos);
    thermometers[ros_name] = w;
    return w;
  }

  // Takes the estimates that arrived and prints them.
  void drain() {
    TcpEstimate e;
    SampleInfo info;
    while (estimates->take_next_sample(&e, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::printf("E %llu %.17g %.17g %.17g\n", (unsigned long long)e.seq(), e.x(), e.y(),
                  e.psi());
      received++;
    }
    std::fflush(stdout);
  }

  static int matched(DataWriter *w) {
    PublicationMatchedStatus s;
    w->get_publication_matched_status(s);
    return s.current_count;
  }

  int estimate_writers() const {
    SubscriptionMatchedStatus s;
    estimates->get_subscription_matched_status(s);
    return s.current_count;
  }

  bool wait_matched(int count, const std::vector<std::string> &topics) {
    for (const auto &t : topics) {
      DataWriter *w = t == "/joint_states" ? joints : thermometer(t);
      while (matched(w) < count) {
        if (Clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    }
    while (estimate_writers() < 1) {
      if (Clock::now() > deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    // the other direction of discovery
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    return true;
  }

  void joint_state(const std::vector<std::string> &f) {
    JointState js;
    js.header().stamp().sec(std::atoi(f[1].c_str()));
    js.header().stamp().nanosec((uint32_t)std::strtoul(f[2].c_str(), nullptr, 10));
    js.name(split(f[3], ','));
    js.position(numbers(f[4]));
    js.velocity(numbers(f[5]));
    js.effort(numbers(f[6]));
    // paced: the k-th state of a run k milliseconds after its start
    auto due = t0 + std::chrono::microseconds(1000 * k);
    std::this_thread::sleep_until(due);
    joints->write(&js);
    k++;
    played++;
  }

  // Plays one script line: 0, or the exit code (2: readers not matched by the deadline, 64: a
  // line it cannot play).
  int step(const std::string &line) {
    std::vector<std::string> f = split(line, ' ');
    if (f.empty()) return 0;
    if (f[0] == "J" && f.size() == 7) {
      joint_state(f);
    } else if (f[0] == "T" && f.size() == 5) {
      Temperature t;
      t.header().stamp().sec(std::atoi(f[2].c_str()));
      t.header().stamp().nanosec((uint32_t)std::strtoul(f[3].c_str(), nullptr, 10));
      t.header().frame_id("thermometer");
      t.temperature(std::strtod(f[4].c_str(), nullptr));
      thermometer(f[1])->write(&t);
    } else if (f[0] == "MATCH" && f.size() >= 3) {
      std::vector<std::string> topics(f.begin() + 2, f.end());
      if (!wait_matched(std::atoi(f[1].c_str()), topics)) {
        std::fprintf(stderr, "fastdds_peer: readers of the cell's topics not matched\n");
        return 2;
      }
      t0 = Clock::now();
      k = 0;
    } else if (f[0] == "WAIT" && f.size() == 2) {
      std::this_thread::sleep_for(std::chrono::duration<double>(std::atof(f[1].c_str())));
      t0 = Clock::now();
      k = 0;
    } else {
      std::fprintf(stderr, "fastdds_peer: cannot play %s\n", line.c_str());
      return 64;
    }
    drain();
    return 0;
  }
};

}  // namespace

int main(int argc, char **argv) {
  if (argc != 5 && argc != 6) {
    std::fprintf(stderr, "usage: fastdds_peer DOMAIN SCRIPT|- COUNT TIMEOUT_S [ENCLAVE_DIR]\n");
    return 64;
  }
  int domain = std::atoi(argv[1]);
  std::string script = argv[2];
  long count = std::atol(argv[3]);
  Peer peer;
  peer.deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                     std::chrono::duration<double>(std::atof(argv[4])));
  peer.participant = DomainParticipantFactory::get_instance()->create_participant(
      domain, participant_qos("fastdds_peer", argc == 6 ? argv[5] : nullptr));
  if (peer.participant == nullptr) {
    std::fprintf(stderr, "fastdds_peer: the participant cannot be created\n");
    return 3;
  }
  for (TypeSupport t : {TypeSupport(new sensor_msgs::msg::dds_::JointState_PubSubType()),
                        TypeSupport(new sensor_msgs::msg::dds_::Temperature_PubSubType()),
                        TypeSupport(new rpkm_msgs::msg::dds_::TcpEstimate_PubSubType())}) {
    t.register_type(peer.participant);
  }
  // the broadcaster's QoS (SystemDefaultsQoS: reliable, volatile, keep last)
  peer.writer_qos = DATAWRITER_QOS_DEFAULT;
  peer.writer_qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
  peer.writer_qos.history().kind = KEEP_LAST_HISTORY_QOS;
  peer.writer_qos.history().depth = 1000;
  peer.publisher = peer.participant->create_publisher(PUBLISHER_QOS_DEFAULT);
  Subscriber *subscriber = peer.participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  DataReaderQos reader_qos = DATAREADER_QOS_DEFAULT;
  reader_qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
  reader_qos.history().kind = KEEP_LAST_HISTORY_QOS;
  reader_qos.history().depth = 4096;
  peer.estimates = subscriber->create_datareader(
      peer.topic("/rpkm/tcp_estimate", "rpkm_msgs::msg::dds_::TcpEstimate_"), reader_qos);
  peer.joints = peer.publisher->create_datawriter(
      peer.topic("/joint_states", "sensor_msgs::msg::dds_::JointState_"), peer.writer_qos);
  if (peer.publisher == nullptr || peer.estimates == nullptr || peer.joints == nullptr) {
    std::fprintf(stderr, "fastdds_peer: endpoints cannot be created\n");
    return 3;
  }
  if (script != "-") {
    std::ifstream in(script);
    std::string line;
    while (std::getline(in, line)) {
      if (int code = peer.step(line)) return code;
    }
  }
  // FASTDDS_PEER_STOP: a file whose appearance ends the listening (the test says when)
  const char *stop = std::getenv("FASTDDS_PEER_STOP");
  while (peer.received < count && Clock::now() < peer.deadline &&
         !(stop != nullptr && std::ifstream(stop).good())) {
    peer.drain();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  std::printf("DONE %ld %d %d\n", peer.received, Peer::matched(peer.joints),
              peer.estimate_writers());
  std::fflush(stdout);
  return peer.received >= count ? 0 : 2;
}

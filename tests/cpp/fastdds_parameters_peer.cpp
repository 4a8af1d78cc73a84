// An independent reader of large samples on eProsima Fast DDS (Debian's libfastrtps, ROS 2's
// default middleware through rmw_fastrtps), its types from fastddsgen
// (fastdds_parameters.idl): reads rpkm_msgs/Parameters (or a blob of bytes) on a DDS topic as
// a ROS 2 node on rmw_fastrtps subscribes to /rpkm/parameters (reliable, transient local; or
// volatile) and prints each sample as tests/python/large_sample_peer.py does:
//
//   S MODEL COUNT NAMES VALUES SIGMAS EFFECTS EFFECT_NAMES EFFECT_VALUES CAL VAL MAX COND
//   B LENGTH HEX
//
// (lists comma-separated, `-` when empty; floats as 16 hex digits of their IEEE 754 bits).
//
//   fastdds_parameters_peer DOMAIN TOPIC parameters|blob COUNT TIMEOUT_S [volatile]
//
// Prints READY once the reader exists, MATCHED once it matched a writer, a line per sample,
// then `DONE n`; exit 0 when COUNT samples arrived, 2 when not by the timeout, 3 when the
// participant or reader cannot be created, 64 on bad usage. Discovery as the other peers: 127.0.0.1 as initial peer; the
// transports are Fast DDS's defaults (its UDP locators are the machine's own addresses).
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/core/status/SubscriptionMatchedStatus.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastrtps/utils/IPLocator.h>

#include "fastdds_parameters.h"
#include "fastdds_parametersPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using Clock = std::chrono::steady_clock;
using Parameters = rpkm_msgs::msg::dds_::Parameters_;
using Blob = rpkm_test::msg::dds_::Blob_;

namespace {

std::string bits(double v) {
  uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  char s[17];
  std::snprintf(s, sizeof s, "%016" PRIx64, b);
  return s;
}

std::string words(const std::vector<std::string> &items) {
  if (items.empty()) return "-";
  std::string out;
  for (const auto &i : items) out += (out.empty() ? "" : ",") + i;
  return out;
}

std::string numbers(const std::vector<double> &v) {
  std::vector<std::string> items;
  for (double x : v) items.push_back(bits(x));
  return words(items);
}

void print(const Parameters &p) {
  std::printf("S %u %u %s %s %s %s %s %s %s %s %s %s\n", (unsigned)p.model(),
              (unsigned)p.measurement_count(), words(p.names()).c_str(),
              numbers(p.values()).c_str(), numbers(p.sigmas()).c_str(),
              words(p.active_effects()).c_str(), words(p.effect_parameter_names()).c_str(),
              numbers(p.effect_parameter_values()).c_str(), bits(p.cal_rms()).c_str(),
              bits(p.val_rms()).c_str(), bits(p.max_abs_residual()).c_str(),
              bits(p.condition_number()).c_str());
  std::fflush(stdout);
}

void print(const Blob &b) {
  std::string hex;
  char d[3];
  for (uint8_t x : b.data()) {
    std::snprintf(d, sizeof d, "%02x", (unsigned)x);
    hex += d;
  }
  std::printf("B %zu %s\n", b.data().size(), hex.empty() ? "-" : hex.c_str());
  std::fflush(stdout);
}

// Takes and prints the samples that arrived; how many.
template <typename T>
long drain(DataReader *reader) {
  long n = 0;
  T sample;
  SampleInfo info;
  while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
    if (!info.valid_data) continue;
    print(sample);
    n++;
  }
  return n;
}

}  // namespace

int main(int argc, char **argv) {
  const bool blob = argc >= 6 && std::strcmp(argv[3], "blob") == 0;
  if ((argc != 6 && argc != 7) || (!blob && std::strcmp(argv[3], "parameters") != 0) ||
      (argc == 7 && std::strcmp(argv[6], "volatile") != 0)) {
    std::fprintf(stderr,
                 "usage: fastdds_parameters_peer DOMAIN TOPIC parameters|blob COUNT TIMEOUT_S "
                 "[volatile]\n");
    return 64;
  }
  long count = std::atol(argv[4]);
  auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                     std::chrono::duration<double>(std::atof(argv[5])));
  DomainParticipantQos pqos = PARTICIPANT_QOS_DEFAULT;
  pqos.name("fastdds_parameters_peer");
  eprosima::fastrtps::rtps::Locator_t peer;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
  pqos.wire_protocol().builtin.initialPeersList.push_back(peer);
  DomainParticipant *participant =
      DomainParticipantFactory::get_instance()->create_participant(std::atoi(argv[1]), pqos);
  if (participant == nullptr) {
    std::fprintf(stderr, "fastdds_parameters_peer: the participant cannot be created\n");
    return 3;
  }
  TypeSupport type(blob ? static_cast<eprosima::fastdds::dds::TopicDataType *>(
                             new rpkm_test::msg::dds_::Blob_PubSubType())
                       : new rpkm_msgs::msg::dds_::Parameters_PubSubType());
  type.register_type(participant);
  Topic *topic = participant->create_topic(argv[2], type.get_type_name(), TOPIC_QOS_DEFAULT);
  Subscriber *subscriber = participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  DataReaderQos qos = DATAREADER_QOS_DEFAULT;
  qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
  qos.durability().kind =
      argc == 7 ? VOLATILE_DURABILITY_QOS : TRANSIENT_LOCAL_DURABILITY_QOS;
  qos.history().kind = KEEP_LAST_HISTORY_QOS;
  qos.history().depth = 16;
  DataReader *reader =
      topic == nullptr || subscriber == nullptr ? nullptr
                                                : subscriber->create_datareader(topic, qos);
  if (reader == nullptr) {
    std::fprintf(stderr, "fastdds_parameters_peer: the reader cannot be created\n");
    return 3;
  }
  std::printf("READY\n");
  std::fflush(stdout);
  long received = 0;
  bool matched = false;
  while (received < count && Clock::now() < deadline) {
    SubscriptionMatchedStatus status;
    reader->get_subscription_matched_status(status);
    if (!matched && status.current_count > 0) {
      matched = true;
      std::printf("MATCHED\n");
      std::fflush(stdout);
    }
    received += blob ? drain<Blob>(reader) : drain<Parameters>(reader);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  std::printf("DONE %ld\n", received);
  std::fflush(stdout);
  return received >= count ? 0 : 2;
}

// Reads a bag folder's metadata.yaml the way rosbag2 does, with yaml-cpp (rosbag2's own YAML
// library), for the two distributions whose `ros2 bag` we promise, and compares its keys with
// the ones rosbag2 writes. Read from ros2/rosbag2 (not copied):
//
// - Jazzy (branch jazzy; rolling is the same): rosbag2_storage/include/rosbag2_storage/yaml.hpp,
//   convert<BagMetadata>::decode and the convert<TopicInformation>, convert<TopicMetadata>,
//   convert<FileInformation> decoders it calls (the keys each metadata version requires);
//   rosbag2_storage/src/rosbag2_storage/qos.cpp, convert<rclcpp::QoS>::decode (a QoS profile:
//   a YAML string up to version 8, a sequence of maps from version 9; enum values as integers
//   or, from version 9, as rmw's names, told apart per profile by the history value) and
//   to_rclcpp_qos_vector; rmw/src/qos_string_conversions.c for the names.
// - Iron (branch iron): the same yaml.hpp decoders less ros_distro, offered_qos_profiles always
//   `as<std::string>()` from version 4 on (so a version-9 sequence is refused), and the player
//   (rosbag2_transport/src/rosbag2_transport/player.cpp, publisher_qos_for_topic) decoding that
//   string with rosbag2_transport/src/rosbag2_transport/qos.cpp, convert<Rosbag2QoS>::decode
//   (every enum `as<int>()`, depth `as<int>()`).
// - The keys rosbag2 writes: the encode() halves of the same convert<> specialisations (every
//   key, whatever the version).
//
// Build: g++ -std=c++17 rosbag2_metadata_check.cpp -lyaml-cpp
// Usage: rosbag2_metadata_check BAG_FOLDER
// Prints "version V topics T messages M files F", then one line each "jazzy: ok",
// "iron: ok", "keys: as rosbag2 writes them", or the reason ("jazzy: refused: ...",
// "keys: ..."). Exit 0 when all three hold, 1 otherwise, 2 when the file cannot be parsed.

#include <cstdint>
#include <functional>
#include <iostream>
#include <set>
#include <string>
#include <vector>

#include "yaml-cpp/yaml.h"

namespace {

// A failed step, named by its path in the file (yaml-cpp's own message kept, as rosbag2
// shows it: "invalid node; first invalid key: ...", "bad conversion").
struct Refused : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// `node[key].as<T>()` as rosbag2 calls it, failures named by `path`.
template <typename T>
T get(const YAML::Node &node, const std::string &key, const std::string &path) {
  try {
    return node[key].as<T>();
  } catch (const YAML::Exception &e) {
    throw Refused(path + "." + key + ": " + e.what());
  }
}

void time_in(const YAML::Node &node, const std::string &key, const char *field,
             const std::string &path) {
  get<std::uint64_t>(node[key], field, path + "." + key);
}

// rmw_time_t's decoder (both distributions): sec and nsec as uint64.
void rmw_time(const YAML::Node &p, const char *key, const std::string &path) {
  get<std::uint64_t>(p[key], "sec", path + "." + key);
  get<std::uint64_t>(p[key], "nsec", path + "." + key);
}

// An rmw policy name as rmw_qos_*_policy_from_str knows it (anything else becomes UNKNOWN,
// which no publisher accepts).
void policy_name(const YAML::Node &p, const char *key, std::set<std::string> known,
                 const std::string &path) {
  const auto name = get<std::string>(p, key, path);
  if (known.count(name) == 0) throw Refused(path + "." + key + ": unknown policy " + name);
}

// Jazzy's convert<rclcpp::QoS>::decode: integers (the version-8 form) when history reads as
// an int in SYSTEM_DEFAULT..UNKNOWN (0..3), rmw names otherwise.
void jazzy_qos(const YAML::Node &p, const std::string &path) {
  int history = -1;
  const bool ints = YAML::convert<int>::decode(p["history"], history) && history >= 0 &&
                    history <= 3;
  if (ints) {
    for (const char *key : {"reliability", "durability", "liveliness"}) get<int>(p, key, path);
  } else {
    policy_name(p, "history", {"system_default", "keep_last", "keep_all"}, path);
    policy_name(p, "reliability", {"system_default", "reliable", "best_effort"}, path);
    policy_name(p, "durability", {"system_default", "transient_local", "volatile"}, path);
    policy_name(p, "liveliness", {"system_default", "automatic", "manual_by_topic"}, path);
  }
  const bool keep_last = ints ? history == 1 : p["history"].as<std::string>() == "keep_last";
  if (keep_last) get<int>(p, "depth", path);
  for (const char *key : {"deadline", "lifespan", "liveliness_lease_duration"}) {
    rmw_time(p, key, path);
  }
  get<bool>(p, "avoid_ros_namespace_conventions", path);
}

// Iron's convert<Rosbag2QoS>::decode (rosbag2_transport/qos.cpp).
void iron_qos(const YAML::Node &p, const std::string &path) {
  for (const char *key : {"history", "reliability", "durability", "liveliness", "depth"}) {
    get<int>(p, key, path);
  }
  for (const char *key : {"deadline", "lifespan", "liveliness_lease_duration"}) {
    rmw_time(p, key, path);
  }
  get<bool>(p, "avoid_ros_namespace_conventions", path);
}

using QosDecoder = std::function<void(const YAML::Node &, const std::string &)>;

// A profile list: every element decoded, a non-sequence refused (decode_for_version).
void qos_list(const YAML::Node &list, const std::string &path, const QosDecoder &decode) {
  if (!list.IsSequence()) throw Refused(path + ": not a sequence of QoS profiles");
  for (std::size_t i = 0; i < list.size(); ++i) {
    decode(list[i], path + "[" + std::to_string(i) + "]");
  }
}

// The YAML string of versions 4..8: empty means no profiles (to_rclcpp_qos_vector, and
// Iron's player skips an empty string).
void qos_string(const YAML::Node &m, const std::string &path, const QosDecoder &decode) {
  const auto text = get<std::string>(m, "offered_qos_profiles", path);
  if (text.empty()) return;
  YAML::Node list;
  try {
    list = YAML::Load(text);
  } catch (const YAML::Exception &e) {
    throw Refused(path + ".offered_qos_profiles: " + e.what());
  }
  qos_list(list, path + ".offered_qos_profiles", decode);
}

enum class Distro { Iron, Jazzy };

// convert<TopicInformation> and convert<TopicMetadata>::decode.
void topic(const YAML::Node &t, int version, Distro distro, const std::string &path) {
  if (!t["topic_metadata"].IsDefined()) throw Refused(path + ".topic_metadata: missing");
  const YAML::Node m = t["topic_metadata"];
  const std::string mp = path + ".topic_metadata";
  for (const char *key : {"name", "type", "serialization_format"}) get<std::string>(m, key, mp);
  if (distro == Distro::Jazzy && version >= 9) {
    qos_list(m["offered_qos_profiles"], mp + ".offered_qos_profiles", jazzy_qos);
  } else if (version >= 4) {
    qos_string(m, mp, distro == Distro::Jazzy ? QosDecoder(jazzy_qos) : QosDecoder(iron_qos));
  }
  if (version >= 7) get<std::string>(m, "type_description_hash", mp);
  get<std::uint64_t>(t, "message_count", path);
}

// convert<BagMetadata>::decode of one distribution.
void decode(const YAML::Node &b, Distro distro) {
  const std::string root = "rosbag2_bagfile_information";
  const int version = get<int>(b, "version", root);
  get<std::string>(b, "storage_identifier", root);
  time_in(b, "duration", "nanoseconds", root);
  time_in(b, "starting_time", "nanoseconds_since_epoch", root);
  get<std::uint64_t>(b, "message_count", root);
  const YAML::Node topics = b["topics_with_message_count"];
  if (!topics.IsSequence()) throw Refused(root + ".topics_with_message_count: not a sequence");
  for (std::size_t i = 0; i < topics.size(); ++i) {
    topic(topics[i], version, distro, root + ".topics_with_message_count[" + std::to_string(i) +
                                          "]");
  }
  get<std::vector<std::string>>(b, "relative_file_paths", root);
  if (version >= 3) {
    get<std::string>(b, "compression_format", root);
    get<std::string>(b, "compression_mode", root);
  }
  if (version >= 5) {
    const YAML::Node files = b["files"];
    if (!files.IsSequence()) throw Refused(root + ".files: not a sequence");
    for (std::size_t i = 0; i < files.size(); ++i) {
      const std::string fp = root + ".files[" + std::to_string(i) + "]";
      get<std::string>(files[i], "path", fp);
      time_in(files[i], "starting_time", "nanoseconds_since_epoch", fp);
      time_in(files[i], "duration", "nanoseconds", fp);
      get<std::uint64_t>(files[i], "message_count", fp);
    }
  }
  if (version >= 6) {
    // convert<unordered_map<string, string>>: as<>() on the key (missing: "invalid node"),
    // then every entry as strings; null, as rosbag2 writes an empty map, has none
    try {
      const YAML::Node custom = b["custom_data"].as<YAML::Node>();
      for (auto it = custom.begin(); it != custom.end(); ++it) {
        it->first.as<std::string>();
        it->second.as<std::string>();
      }
    } catch (const YAML::Exception &e) {
      throw Refused(root + ".custom_data: " + e.what());
    }
  }
  if (distro == Distro::Jazzy && version >= 8) get<std::string>(b, "ros_distro", root);
}

// The keys of a map against those rosbag2's encode() writes there.
void keys(const YAML::Node &map, const std::set<std::string> &written, const std::string &path,
          std::vector<std::string> &problems) {
  if (!map.IsMap()) {
    problems.push_back(path + ": not a map");
    return;
  }
  std::set<std::string> seen;
  for (auto it = map.begin(); it != map.end(); ++it) seen.insert(it->first.as<std::string>());
  for (const auto &key : written) {
    if (seen.count(key) == 0) problems.push_back(path + ": no " + key);
  }
  for (const auto &key : seen) {
    if (written.count(key) == 0) problems.push_back(path + ": " + key + " (rosbag2 has none)");
  }
}

void qos_keys(const YAML::Node &list, const std::string &path,
              std::vector<std::string> &problems) {
  for (std::size_t i = 0; list.IsSequence() && i < list.size(); ++i) {
    const std::string qp = path + "[" + std::to_string(i) + "]";
    keys(list[i],
         {"history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
          "liveliness_lease_duration", "avoid_ros_namespace_conventions"},
         qp, problems);
    for (const char *t : {"deadline", "lifespan", "liveliness_lease_duration"}) {
      keys(list[i][t], {"sec", "nsec"}, qp + "." + t, problems);
    }
  }
}

// Every map rosbag2 writes (convert<...>::encode), key for key.
std::vector<std::string> written_keys(const YAML::Node &b) {
  std::vector<std::string> problems;
  const std::string root = "rosbag2_bagfile_information";
  keys(b,
       {"version", "storage_identifier", "duration", "starting_time", "message_count",
        "topics_with_message_count", "compression_format", "compression_mode",
        "relative_file_paths", "files", "custom_data", "ros_distro"},
       root, problems);
  keys(b["duration"], {"nanoseconds"}, root + ".duration", problems);
  keys(b["starting_time"], {"nanoseconds_since_epoch"}, root + ".starting_time", problems);
  const YAML::Node topics = b["topics_with_message_count"];
  for (std::size_t i = 0; topics.IsSequence() && i < topics.size(); ++i) {
    const std::string tp = root + ".topics_with_message_count[" + std::to_string(i) + "]";
    keys(topics[i], {"topic_metadata", "message_count"}, tp, problems);
    const YAML::Node m = topics[i]["topic_metadata"];
    keys(m, {"name", "type", "serialization_format", "offered_qos_profiles",
             "type_description_hash"},
         tp + ".topic_metadata", problems);
    const YAML::Node qos = m["offered_qos_profiles"];
    const std::string qp = tp + ".topic_metadata.offered_qos_profiles";
    if (qos.IsScalar() && !qos.Scalar().empty()) {
      try {
        qos_keys(YAML::Load(qos.Scalar()), qp, problems);
      } catch (const YAML::Exception &e) {
        problems.push_back(qp + ": " + e.what());
      }
    } else {
      qos_keys(qos, qp, problems);
    }
  }
  const YAML::Node files = b["files"];
  for (std::size_t i = 0; files.IsSequence() && i < files.size(); ++i) {
    const std::string fp = root + ".files[" + std::to_string(i) + "]";
    keys(files[i], {"path", "starting_time", "duration", "message_count"}, fp, problems);
  }
  return problems;
}

std::string verdict(const YAML::Node &b, Distro distro) {
  try {
    decode(b, distro);
    return "ok";
  } catch (const std::exception &e) {
    return std::string("refused: ") + e.what();
  }
}

}  // namespace

int main(int argc, char **argv) {
  if (argc != 2) {
    std::cerr << "usage: rosbag2_metadata_check BAG_FOLDER\n";
    return 2;
  }
  YAML::Node b;
  try {
    b = YAML::LoadFile(std::string(argv[1]) + "/metadata.yaml")["rosbag2_bagfile_information"];
  } catch (const YAML::Exception &e) {
    std::cout << "unreadable: " << e.what() << "\n";
    return 2;
  }
  const YAML::Node topics = b["topics_with_message_count"];
  const YAML::Node files = b["files"];
  std::cout << "version " << b["version"].as<std::string>("?") << " topics "
            << (topics.IsSequence() ? topics.size() : 0) << " messages "
            << b["message_count"].as<std::string>("?") << " files "
            << (files.IsSequence() ? files.size() : 0) << "\n";
  const std::string jazzy = verdict(b, Distro::Jazzy);
  const std::string iron = verdict(b, Distro::Iron);
  std::string key_verdict = "as rosbag2 writes them";
  const auto problems = written_keys(b);
  if (!problems.empty()) {
    key_verdict.clear();
    for (const auto &p : problems) key_verdict += (key_verdict.empty() ? "" : "; ") + p;
  }
  std::cout << "jazzy: " << jazzy << "\niron: " << iron << "\nkeys: " << key_verdict << "\n";
  return jazzy == "ok" && iron == "ok" && problems.empty() ? 0 : 1;
}

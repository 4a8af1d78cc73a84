// Reads a bag folder's metadata.yaml the way rosbag2's storage layer does (Iron and Jazzy,
// metadata versions up to 8): every key the reader requires for the file's version is
// converted with yaml-cpp's `as<T>()`, so a missing or mistyped key fails with yaml-cpp's own
// message ("invalid node; first invalid key: ..."), as `ros2 bag info` would. The per-version
// rules follow rosbag2_storage/include/rosbag2_storage/yaml.hpp (read, not copied); the QoS
// profiles, a YAML string up to version 8, are decoded as rosbag2_transport's qos.cpp reads them.
//
// Build: g++ -std=c++17 rosbag2_metadata_check.cpp -lyaml-cpp
// Usage: rosbag2_metadata_check BAG_FOLDER   (prints "ok version V topics T messages M files F")

#include <cstdint>
#include <iostream>
#include <string>

#include "yaml-cpp/yaml.h"

namespace {

std::uint64_t nanoseconds(const YAML::Node &node, const char *key) {
  return node[key].as<std::uint64_t>();
}

// One profile of `offered_qos_profiles` (version < 9: enums as integers).
void check_qos_profile(const YAML::Node &p) {
  for (const char *key : {"history", "reliability", "durability", "liveliness"}) {
    p[key].as<int>();
  }
  p["depth"].as<std::uint64_t>();
  for (const char *key : {"deadline", "lifespan", "liveliness_lease_duration"}) {
    p[key]["sec"].as<std::uint64_t>();
    p[key]["nsec"].as<std::uint64_t>();
  }
  p["avoid_ros_namespace_conventions"].as<bool>();
}

void check_topic(const YAML::Node &t, int version) {
  const YAML::Node m = t["topic_metadata"];
  m["name"].as<std::string>();
  m["type"].as<std::string>();
  m["serialization_format"].as<std::string>();
  if (version >= 4) {
    const std::string qos = m["offered_qos_profiles"].as<std::string>();
    if (!qos.empty()) {
      const YAML::Node profiles = YAML::Load(qos);
      if (!profiles.IsSequence()) {
        throw std::runtime_error("offered_qos_profiles of " + m["name"].as<std::string>() +
                                 " is not a sequence");
      }
      for (const auto &p : profiles) check_qos_profile(p);
    }
  }
  if (version >= 7) m["type_description_hash"].as<std::string>();
  t["message_count"].as<std::uint64_t>();
}

}  // namespace

int main(int argc, char **argv) {
  if (argc != 2) {
    std::cerr << "usage: rosbag2_metadata_check BAG_FOLDER\n";
    return 2;
  }
  try {
    const YAML::Node root = YAML::LoadFile(std::string(argv[1]) + "/metadata.yaml");
    const YAML::Node b = root["rosbag2_bagfile_information"];
    const int version = b["version"].as<int>();
    if (version > 8) {
      throw std::runtime_error("version " + std::to_string(version) + " is newer than 8");
    }
    b["storage_identifier"].as<std::string>();
    nanoseconds(b["duration"], "nanoseconds");
    nanoseconds(b["starting_time"], "nanoseconds_since_epoch");
    const auto messages = b["message_count"].as<std::uint64_t>();
    const YAML::Node topics = b["topics_with_message_count"];
    if (!topics.IsSequence()) throw std::runtime_error("topics_with_message_count: not a sequence");
    for (const auto &t : topics) check_topic(t, version);
    b["relative_file_paths"].as<std::vector<std::string>>();
    if (version >= 3) {
      b["compression_format"].as<std::string>();
      b["compression_mode"].as<std::string>();
    }
    std::size_t files = 0;
    if (version >= 5) {
      for (const auto &f : b["files"]) {
        f["path"].as<std::string>();
        nanoseconds(f["starting_time"], "nanoseconds_since_epoch");
        nanoseconds(f["duration"], "nanoseconds");
        f["message_count"].as<std::uint64_t>();
        ++files;
      }
    }
    if (version >= 6) {
      // a map of strings; rosbag2 itself writes an empty one as null
      const YAML::Node custom = b["custom_data"];
      if (!custom.IsDefined()) throw YAML::InvalidNode("custom_data");
      for (auto it = custom.begin(); it != custom.end(); ++it) {
        it->first.as<std::string>();
        it->second.as<std::string>();
      }
    }
    if (version >= 8) b["ros_distro"].as<std::string>();
    std::cout << "ok version " << version << " topics " << topics.size() << " messages "
              << messages << " files " << files << "\n";
    return 0;
  } catch (const std::exception &e) {
    std::cout << "refused: " << e.what() << "\n";
    return 1;
  }
}

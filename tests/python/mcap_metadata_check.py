#!/usr/bin/env python3
"""Compare a bag's metadata.yaml with the metadata rosbag2 derives from its MCAP file.

    mcap_metadata_check.py BAG_FOLDER   -> {"compared": n, "mismatches": [...]} on stdout

rosbag2's MCAP storage plugin builds a bag's metadata from the file itself when it has no
metadata.yaml (`ros2 bag info file.mcap`, `ros2 bag reindex`): ros2/rosbag2 branch jazzy,
rosbag2_storage_mcap/src/mcap_storage.cpp, MCAPStorage::read_metadata (read, not copied):
message_count, starting_time and duration from the Statistics record (messageCount,
messageStartTime, messageEndTime - messageStartTime); per channel, the topic's name, its
schema's name as type, the message encoding as serialization_format, the channel metadata
`offered_qos_profiles` and `topic_type_hash`, and the channel's count in
channelMessageCounts (0 when absent). A metadata.yaml that says otherwise describes another
bag than the one `ros2 bag play` reads. The file is read with the `mcap` package, the YAML
with ruamel (both independent of rpkm). Used by tests/it/bag_rosbag2_metadata.rs.
"""

import json
import sys
from pathlib import Path

from mcap.reader import make_reader
from ruamel.yaml import YAML


def from_storage(path):
    """What MCAPStorage::read_metadata fills in, from one MCAP file."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        raise SystemExit(f"{path}: no summary with a Statistics record")
    stats = summary.statistics
    topics = {}
    for channel in summary.channels.values():
        schema = summary.schemas.get(channel.schema_id)
        topics[channel.topic] = {
            "type": schema.name if schema else None,
            "serialization_format": channel.message_encoding,
            "offered_qos_profiles": channel.metadata.get("offered_qos_profiles"),
            "type_description_hash": channel.metadata.get("topic_type_hash"),
            "message_count": stats.channel_message_counts.get(channel.id, 0),
        }
    return {
        "message_count": stats.message_count,
        "starting_time": stats.message_start_time,
        "duration": stats.message_end_time - stats.message_start_time,
        "topics": topics,
    }


def profiles(value):
    """QoS profiles as data: a YAML string (versions 4..8, and channel metadata) or a list."""
    if isinstance(value, str):
        return YAML(typ="safe").load(value) if value else []
    return value


def compare(name, expected, actual, mismatches):
    if expected != actual:
        mismatches.append(f"{name}: metadata.yaml {actual!r}, MCAP file {expected!r}")


def check(bag):
    info = YAML(typ="safe").load((bag / "metadata.yaml").read_text())
    info = info["rosbag2_bagfile_information"]
    files = info["relative_file_paths"]
    if len(files) != 1:
        raise SystemExit(f"{bag}: {len(files)} storage files; this check reads one")
    storage = from_storage(bag / files[0])
    mismatches = []
    compare("message_count", storage["message_count"], info["message_count"], mismatches)
    compare("starting_time", storage["starting_time"],
            info["starting_time"]["nanoseconds_since_epoch"], mismatches)
    compare("duration", storage["duration"], info["duration"]["nanoseconds"], mismatches)
    for entry in info.get("files", []):
        compare(f"files[{entry['path']}].message_count", storage["message_count"],
                entry["message_count"], mismatches)
    listed = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    compare("topics", sorted(storage["topics"]), sorted(listed), mismatches)
    compared = 3
    for name, derived in storage["topics"].items():
        if name not in listed:
            continue
        meta = listed[name]["topic_metadata"]
        for key in ("type", "serialization_format"):
            compare(f"{name}.{key}", derived[key], meta.get(key), mismatches)
        compare(f"{name}.offered_qos_profiles", profiles(derived["offered_qos_profiles"]),
                profiles(meta.get("offered_qos_profiles")), mismatches)
        if derived["type_description_hash"] is not None:
            compare(f"{name}.type_description_hash", derived["type_description_hash"],
                    meta.get("type_description_hash"), mismatches)
        compare(f"{name}.message_count", derived["message_count"],
                listed[name]["message_count"], mismatches)
        compared += 5
    return {"compared": compared, "mismatches": mismatches}


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    print(json.dumps(check(Path(sys.argv[1]))))

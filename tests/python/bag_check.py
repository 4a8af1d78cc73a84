#!/usr/bin/env python3
"""Decode every message of a rosbag2 MCAP bag with two independent readers and print JSON.

    bag_check.py <bag folder>            -> {"mcap_ros2": [...], "rosbags": [...]}
    bag_check.py <bag folder> --bench    -> {"reader": "mcap_ros2", "messages": n, "seconds": s}

Readers:
- mcap_ros2 (PyPI mcap-ros2-support): decodes with the schemas stored in the .mcap files.
- rosbags (PyPI rosbags): opens the folder through metadata.yaml with its rosbag2 Reader and
  decodes with a type store registered from the bag's own message definitions (no built-in
  types), so a definition that does not describe the payload fails here.

Each message is {"topic", "type", "log_time" (ns), "value"} where value is the decoded message
as nested JSON objects (arrays as lists). Floats are printed with repr, i.e. exactly.
Used by nodes/transport/tests/bag_python_readers.rs and benches/bag_replay.rs.
"""

import dataclasses
import json
import math
import sys
import time
from pathlib import Path


def plain(value):
    """A decoded message (either reader's representation) as plain JSON data; a float that is
    not finite (a Parameters' val_rms without held-out data) as null, as rpkm's JSON has it."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if hasattr(value, "tolist"):  # numpy arrays and scalars (rosbags)
        return plain(value.tolist())
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if dataclasses.is_dataclass(value):  # rosbags messages
        return {
            f.name: plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            # __msgtype__, and constants (ROS constants are upper case, fields lower case)
            if not f.name.startswith("__") and not f.name.isupper()
        }
    slots = getattr(type(value), "__slots__", None)
    if slots:  # mcap_ros2 messages
        return {name: plain(getattr(value, name)) for name in slots}
    raise TypeError(f"cannot convert {type(value).__name__} to JSON")


def mcap_files(bag):
    """The storage files of a bag folder (from metadata.yaml when present) or a bare file."""
    bag = Path(bag)
    if bag.is_file():
        return [bag]
    meta = bag / "metadata.yaml"
    if meta.is_file():
        from ruamel.yaml import YAML  # installed with rosbags

        info = YAML(typ="safe").load(meta.read_text())["rosbag2_bagfile_information"]
        return [bag / Path(p).name for p in info["relative_file_paths"]]
    return sorted(bag.glob("*.mcap"))


def read_mcap_ros2(bag, keep=True):
    from mcap_ros2.reader import read_ros2_messages

    out = []
    count = 0
    for path in mcap_files(bag):
        for m in read_ros2_messages(str(path), log_time_order=True):
            count += 1
            if keep:
                out.append(
                    {
                        "topic": m.channel.topic,
                        "type": m.schema.name,
                        "log_time": m.log_time_ns,
                        "value": plain(m.ros_msg),
                    }
                )
    return out if keep else count


def read_rosbags(bag):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    typestore = get_typestore(Stores.EMPTY)
    out = []
    with Reader(bag) as reader:
        types = {}
        for conn in reader.connections:
            if conn.msgdef.data:
                types.update(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        typestore.register(types)
        for conn, timestamp, raw in reader.messages():
            msg = typestore.deserialize_cdr(raw, conn.msgtype)
            out.append(
                {
                    "topic": conn.topic,
                    "type": conn.msgtype,
                    "log_time": timestamp,
                    "value": plain(msg),
                }
            )
    return out


def main(argv):
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    bag = argv[1]
    if "--bench" in argv[2:]:
        start = time.perf_counter()
        count = read_mcap_ros2(bag, keep=False)
        seconds = time.perf_counter() - start
        print(json.dumps({"reader": "mcap_ros2", "messages": count, "seconds": seconds}))
        return 0
    result = {"mcap_ros2": read_mcap_ros2(bag), "rosbags": read_rosbags(bag)}
    json.dump(result, sys.stdout, allow_nan=False)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

#!/usr/bin/env python3
"""Write a small rosbag2 MCAP bag with the rosbags library (not rpkm), in a metadata version.

    rosbags_write.py BAG_FOLDER VERSION     (VERSION 8 or 9, as rosbags' Writer supports)

Three std_msgs/msg/String messages on /chatter at 1000, 1001, 1002 ns, offered with one QoS
profile (keep last 7, best effort, transient local, infinite durations). Version 9 is the
layout rosbag2 on Jazzy writes (QoS profiles as a YAML sequence with rmw's policy names),
version 8 the one before (QoS as a YAML string, policies as integers). Used by
tests/it/bag_rosbag2_metadata.rs to check that rpkm reads both and that the rosbag2 metadata
checker accepts what a rosbag2-compatible writer other than rpkm produces.
"""

import sys
from pathlib import Path

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    out, version = Path(sys.argv[1]), int(sys.argv[2])
    store = get_typestore(Stores.ROS2_JAZZY)
    string = store.types["std_msgs/msg/String"]
    infinite = QosTime(9223372036, 854775807)
    qos = Qos(QosHistory.KEEP_LAST, 7, QosReliability.BEST_EFFORT,
              QosDurability.TRANSIENT_LOCAL, infinite, infinite, QosLiveliness.AUTOMATIC,
              infinite, False)
    with Writer(out, version=version, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store,
                                     offered_qos_profiles=[qos])
        for i in range(3):
            data = store.serialize_cdr(string(data=f"m{i}"), "std_msgs/msg/String")
            writer.write(conn, 1000 + i, data)


if __name__ == "__main__":
    main()

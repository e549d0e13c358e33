"""Reads a ROS 2 bag's .mcap with the reference readers (PyPI mcap for the
container, rosbags for the messages: each channel's type built from the
definition text the bag carries, every message deserialized from its CDR)
and prints what the bag export test checks, as JSON: the header's profile;
per topic the type, schema and message encodings, the message count and
whether log times never decrease; the frames of /odom, /tf and /tf_static;
the first cloud's size and fields and its returns; the first commands; the
marker types and the most points a marker holds per topic."""

import json
import math
import sys

from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

typestore = get_typestore(Stores.EMPTY)
registered = set()
topics = {}
out = {"clouds": [], "commands": [], "markers": {}, "frames": {}}

with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    out["profile"] = reader.get_header().profile
    for schema, channel, message in reader.iter_messages():
        if schema.name not in registered:
            typestore.register(get_types_from_msg(schema.data.decode(), schema.name))
            registered.add(schema.name)
        msg = typestore.deserialize_cdr(message.data, schema.name)
        t = topics.setdefault(channel.topic, {
            "type": schema.name,
            "schema_encoding": schema.encoding,
            "encoding": channel.message_encoding,
            "qos": channel.metadata.get("offered_qos_profiles", ""),
            "count": 0,
            "increasing": True,
            "last": -1,
        })
        t["count"] += 1
        t["increasing"] &= message.log_time >= t["last"]
        t["last"] = message.log_time
        name = schema.name.split("/")[-1]
        if name == "Odometry":
            out["frames"]["/odom"] = [msg.header.frame_id, msg.child_frame_id]
        elif name == "TFMessage":
            out["frames"][channel.topic] = [[x.header.frame_id, x.child_frame_id] for x in msg.transforms]
        elif name == "PointCloud2" and len(out["clouds"]) < 1:
            step = msg.point_step
            data = bytes(msg.data)
            import struct
            returns = 0
            for i in range(msg.height * msg.width):
                x, y, z, r = struct.unpack_from("<4f", data, i * step)
                if not math.isnan(r):
                    returns += 1
                    # The range is the point's distance from the sensor.
                    assert abs(math.sqrt(x * x + y * y + z * z) - r) < 1e-3 * r + 1e-4, (x, y, z, r)
            out["clouds"].append({
                "frame": msg.header.frame_id,
                "height": msg.height,
                "width": msg.width,
                "fields": [[p.name, p.offset, p.datatype] for p in msg.fields],
                "point_step": step,
                "returns": returns,
                "stamp": msg.header.stamp.sec * 1_000_000 + msg.header.stamp.nanosec // 1000,
            })
        elif name == "AckermannDriveStamped" and len(out["commands"]) < 50:
            out["commands"].append({
                "utime": msg.header.stamp.sec * 1_000_000 + msg.header.stamp.nanosec // 1000,
                "steering_angle": msg.drive.steering_angle,
                "speed": msg.drive.speed,
            })
        elif name == "MarkerArray":
            m = out["markers"].setdefault(channel.topic, {"types": [], "frames": [], "most_points": 0})
            for marker in msg.markers:
                if marker.type not in m["types"]:
                    m["types"].append(marker.type)
                if marker.header.frame_id not in m["frames"]:
                    m["frames"].append(marker.header.frame_id)
                m["most_points"] = max(m["most_points"], len(marker.points))

out["topics"] = {k: {x: v[x] for x in ("type", "schema_encoding", "encoding", "qos", "count", "increasing")} for k, v in topics.items()}
print(json.dumps(out))

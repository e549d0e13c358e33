"""Reads an MCAP file with the reference readers (PyPI mcap, mcap-protobuf-support
and Foxglove's protobuf schemas) and prints what the export test checks, as JSON:
per topic the message count, schema and encoding, whether log times never
decrease; the points of the first point cloud and its frame; the arcs of the
first /arcs scene; the most patches a /local_map scene holds; the fields of
the first steering command."""

import json
import sys

from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

topics = {}
first = {}
most_patches = 0
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for schema, channel, message in reader.iter_messages():
        t = topics.setdefault(channel.topic, {
            "count": 0,
            "schema": schema.name if schema else "",
            "encoding": channel.message_encoding,
            "increasing": True,
            "last": -1,
        })
        t["count"] += 1
        if message.log_time < t["last"]:
            t["increasing"] = False
        t["last"] = message.log_time
        if channel.topic not in first:
            first[channel.topic] = message.data
        if channel.topic == "/local_map":
            scene = SceneUpdate()
            scene.ParseFromString(message.data)
            most_patches = max(most_patches, len(scene.entities[0].cubes))

result = {"topics": {k: {x: v[x] for x in ("count", "schema", "encoding", "increasing")} for k, v in topics.items()}}
clouds = [t for t in first if t.startswith("/range_image")]
if clouds:
    cloud = PointCloud()
    cloud.ParseFromString(first[clouds[0]])
    result["cloud"] = {
        "topic": clouds[0],
        "points": len(cloud.data) // cloud.point_stride,
        "frame": cloud.frame_id,
        "fields": [f.name for f in cloud.fields],
    }
if "/arcs" in first:
    scene = SceneUpdate()
    scene.ParseFromString(first["/arcs"])
    result["arcs"] = {"frame": scene.entities[0].frame_id, "lines": len(scene.entities[0].lines)}
result["most_local_map_patches"] = most_patches
if "/steering_command" in first:
    result["command"] = json.loads(first["/steering_command"])
print(json.dumps(result))

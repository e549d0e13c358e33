"""A ROS 2 bag's .mcap rewritten by the reference writer (PyPI mcap):
chunks compressed with zstd and their CRCs written; optionally with
sensor_msgs/PointCloud2's schema naming row_step row_stride (a schema
unlike ROS 2's, the messages as they were). Used by lcm_to_bag.py and to
make tests/bags/ouster-os1-128.mcap.

    python mcap_rewrite.py BAG_DIR [--rename-row-step]
"""

import sys


def rewrite(out, rename_row_step=False):
    """Rewrites the bag's .mcap with the reference `mcap` package (chunks
    compressed with zstd, their CRCs written); with `rename_row_step`,
    /points' schema names row_step row_stride: a schema unlike ROS 2's,
    the messages as they were."""
    from pathlib import Path

    from mcap.reader import make_reader
    from mcap.writer import Writer

    path = next(Path(out).glob("*.mcap"))
    with open(path, "rb") as f:
        reader = make_reader(f)
        messages = [(s, c, m) for s, c, m in reader.iter_messages()]
    schemas, channels = {}, {}
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="lcm_to_bag.py")
        for schema, channel, message in messages:
            if schema.id not in schemas:
                data = schema.data
                if rename_row_step and schema.name == "sensor_msgs/msg/PointCloud2":
                    data = data.replace(b"uint32 row_step", b"uint32 row_stride")
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id]
                )
            writer.add_message(
                channels[channel.id], message.log_time, message.data, message.publish_time, message.sequence
            )
        writer.finish()



if __name__ == "__main__":
    rewrite(sys.argv[1], "--rename-row-step" in sys.argv[2:])

"""Seeds for the `ros2_bag`, `ros1_bag` and `cdr_messages` fuzz targets,
written by the reference tools (PyPI rosbags for the messages and ROS 1
bags, PyPI mcap for MCAP files): a few-kilobyte bag of every kind a replay
reads (an organized cloud of 2 x 4 points with per-point times, a ring cloud, odometry, a pose,
/tf and /tf_static), as ROS 2 (plain and zstd), as ROS 1 (plain, bz2,
lz4) and as ROS 1 messages in MCAP, and each message's CDR bytes alone.

    python bag_seeds.py FUZZ_CORPUS_DIR

writes FUZZ_CORPUS_DIR/{ros2_bag,ros1_bag,cdr_messages}/seed-*.
"""

import sys
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
T = ts.types
ROS1 = False


def use_ros1():
    """The messages below as ROS 1 (Noetic) has them: a header with `seq`."""
    global ts, T, ROS1
    from rosbags.typesys import get_types_from_msg

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    ROS1 = True


def header(sec, frame):
    stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=0)
    if ROS1:
        return T["std_msgs/msg/Header"](seq=sec, stamp=stamp, frame_id=frame)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def cloud(sec, ring):
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
    points = [(5.0, 1.0, -1.0), (5.0, -1.0, -1.0), (6.0, 0.5, -1.2), (float("nan"),) * 3,
              (4.0, 1.0, -0.8), (4.0, -1.0, -0.8), (0.0, 0.0, 0.0), (7.0, 0.0, -1.5)]
    if ring:
        fields.append(T["sensor_msgs/msg/PointField"](name="ring", offset=12, datatype=4, count=1))
        dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("ring", "<u2"), ("pad", "<u2")]
        data = np.array([p + (i % 2, 0) for i, p in enumerate(points)], dtype=dtype)
        height, width, step = 1, 8, 16
    else:
        # Ouster's per-point time `t` (uint32, ns after the stamp): each
        # column 25 ms after the one before.
        fields.append(T["sensor_msgs/msg/PointField"](name="t", offset=12, datatype=6, count=1))
        dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")]
        data = np.array([p + ((i % 4) * 25_000_000,) for i, p in enumerate(points)], dtype=dtype)
        height, width, step = 2, 4, 16
    return T["sensor_msgs/msg/PointCloud2"](
        header=header(sec, "lidar"), height=height, width=width, fields=fields, is_bigendian=False,
        point_step=step, row_step=step * width, data=np.frombuffer(data.tobytes(), dtype=np.uint8),
        is_dense=False,
    )


def pose(x):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )


def transform(sec, parent, child, x, z):
    return T["geometry_msgs/msg/TransformStamped"](
        header=header(sec, parent), child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=z),
            rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
    )


def odometry(sec):
    zero = np.zeros(36)
    twist = T["geometry_msgs/msg/Twist"](
        linear=T["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0),
        angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.1),
    )
    return T["nav_msgs/msg/Odometry"](
        header=header(sec, "odom"), child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose(float(sec)), covariance=zero),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=zero),
    )


def messages():
    """(topic, type, message) in time order, a second apart."""
    tf = "tf2_msgs/msg/TFMessage"
    yield 0, "/tf_static", tf, T[tf](transforms=[transform(0, "base_link", "lidar", 1.0, 2.0)])
    for sec in range(1, 3):
        yield sec, "/odom", "nav_msgs/msg/Odometry", odometry(sec)
        yield sec, "/pose", "geometry_msgs/msg/PoseStamped", T["geometry_msgs/msg/PoseStamped"](
            header=header(sec, "odom"), pose=pose(float(sec)))
        yield sec, "/tf", tf, T[tf](transforms=[transform(sec, "odom", "base_link", float(sec), 0.0)])
        yield sec, "/points", "sensor_msgs/msg/PointCloud2", cloud(sec, ring=False)
        yield sec, "/velodyne_points", "sensor_msgs/msg/PointCloud2", cloud(sec, ring=True)


def main():
    root = Path(sys.argv[1])
    bags, cdr = root / "ros2_bag", root / "cdr_messages"
    bags.mkdir(parents=True, exist_ok=True)
    cdr.mkdir(parents=True, exist_ok=True)
    written = set()
    for name, compression in (("seed-plain", CompressionType.NONE), ("seed-zstd", CompressionType.ZSTD)):
        with open(bags / f"{name}.mcap", "wb") as f:
            writer = Writer(f, compression=compression)
            writer.start(profile="ros2", library="bag_seeds.py")
            channels = {}
            for sec, topic, msgtype, msg in messages():
                if topic not in channels:
                    text, _ = ts.generate_msgdef(msgtype, ros_version=2)
                    schema = writer.register_schema(msgtype, "ros2msg", text.encode())
                    channels[topic] = writer.register_channel(topic, "cdr", schema)
                data = ts.serialize_cdr(msg, msgtype)
                writer.add_message(channels[topic], sec * 10**9, bytes(data), sec * 10**9)
                if msgtype not in written:
                    (cdr / f"seed-{msgtype.split('/')[-1]}").write_bytes(bytes(data))
                    written.add(msgtype)
            writer.finish()
    use_ros1()
    from rosbags.rosbag1 import Writer as Ros1Writer

    ros1 = root / "ros1_bag"
    ros1.mkdir(parents=True, exist_ok=True)
    for compression in ("none", "bz2", "lz4"):
        path = ros1 / f"seed-{compression}.bag"
        path.unlink(missing_ok=True)
        writer = Ros1Writer(path)
        if compression != "none":
            writer.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
        with writer:
            connections = {}
            for sec, topic, msgtype, msg in messages():
                if topic not in connections:
                    connections[topic] = writer.add_connection(topic, msgtype, typestore=ts)
                writer.write(connections[topic], sec * 10**9, bytes(ts.serialize_ros1(msg, msgtype)))
    # ROS 1 messages in an MCAP file (what `mcap convert` makes of a bag).
    with open(bags / "seed-ros1-encoded.mcap", "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros1", library="bag_seeds.py")
        channels = {}
        for sec, topic, msgtype, msg in messages():
            if topic not in channels:
                text, _ = ts.generate_msgdef(msgtype, ros_version=1)
                schema = writer.register_schema(msgtype.replace("/msg/", "/"), "ros1msg", text.encode())
                channels[topic] = writer.register_channel(topic, "ros1", schema)
            data = bytes(ts.serialize_ros1(msg, msgtype))
            writer.add_message(channels[topic], sec * 10**9, data, sec * 10**9)
        writer.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Real lidar frames as a ROS 2 bag, for the bag replay tests: the frames of
a pcap of the Ouster SDK's test data, decoded by the Ouster SDK itself
(PyPI ouster-sdk), written by the reference writer (PyPI rosbags).

How tests/bags/ouster-os1-128.mcap was made (the pcap and its metadata
are in the Ouster SDK's source distribution, ouster_sdk-1.0.1.tar.gz on
PyPI, under sdk/tests/pcaps/; BSD 3-Clause, see tests/bags/README.md):

    python3 -m venv /tmp/ouster && /tmp/ouster/bin/pip install ouster-sdk==1.0.1 rosbags==0.11.9
    /tmp/ouster/bin/python tests/tools/ouster_to_bag.py \
        OS-1-128_v2.3.0_1024x10_lb_n3.pcap OS-1-128_v2.3.0_1024x10.json OUT_DIR --height 2.0

Each complete frame becomes an organized sensor_msgs/PointCloud2 on
/os_cloud (128 x 1024, destaggered, x y z float32 in the sensor frame,
NaN where there was no return), stamped with the frame's first column
time. The sensor stood still: nav_msgs/Odometry at 50 Hz on /odom holds
the identity pose from the first frame to a second past the last, and /tf_static mounts os_sensor
`--height` metres above base_link (the ground lies about 2.0 m below the
sensor in these frames).
"""

import argparse
import sys

import numpy as np
from ouster.sdk import open_source
from ouster.sdk.core import XYZLut, destagger
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
T = ts.types


def header(ns, frame):
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pcap")
    parser.add_argument("metadata")
    parser.add_argument("out")
    parser.add_argument("--height", type=float, required=True, help="of the sensor above the ground, m")
    args = parser.parse_args()

    source = open_source(args.pcap, meta=[args.metadata])
    info = source.sensor_info[0]
    lut = XYZLut(info)
    frames = []
    for scans in source:
        scan = scans[0]
        if scan is None or "RANGE" not in scan.fields or not scan.complete():
            continue
        xyz = destagger(info, lut(scan.field("RANGE"))).astype(np.float32)
        rng = destagger(info, scan.field("RANGE"))
        xyz[rng == 0] = np.nan
        stamps = scan.timestamp[scan.timestamp > 0]
        frames.append((int(stamps.min()), xyz))

    with Writer(args.out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = "tf2_msgs/msg/TFMessage"
        odom = "nav_msgs/msg/Odometry"
        cloud = "sensor_msgs/msg/PointCloud2"
        c_tf = writer.add_connection("/tf_static", tf, typestore=ts)
        c_odom = writer.add_connection("/odom", odom, typestore=ts)
        c_cloud = writer.add_connection("/os_cloud", cloud, typestore=ts)
        # Poses to a second past the last frame: its cells reach the map
        # `pipeline.perception_latency_s` after its capture.
        start, end = frames[0][0], frames[-1][0] + 1_000_000_000
        mount = T["geometry_msgs/msg/TransformStamped"](
            header=header(start, "base_link"),
            child_frame_id="os_sensor",
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=args.height),
                rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )
        writer.write(c_tf, start, ts.serialize_cdr(T[tf](transforms=[mount]), tf))
        zero = np.zeros(36)
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        still = T["geometry_msgs/msg/Twist"](
            linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        )
        messages = []
        for t in range(start - 20_000_000, end + 20_000_000, 20_000_000):
            msg = T[odom](
                header=header(t, "odom"),
                child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zero),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=still, covariance=zero),
            )
            messages.append((t, c_odom, ts.serialize_cdr(msg, odom)))
        fields = [T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
        for t, xyz in frames:
            rows, cols, _ = xyz.shape
            msg = T[cloud](
                header=header(t, "os_sensor"), height=rows, width=cols, fields=fields, is_bigendian=False,
                point_step=12, row_step=12 * cols,
                data=np.frombuffer(np.ascontiguousarray(xyz).tobytes(), dtype=np.uint8), is_dense=False,
            )
            messages.append((t, c_cloud, ts.serialize_cdr(msg, cloud)))
        for t, connection, data in sorted(messages, key=lambda m: m[0]):
            writer.write(connection, t, data)
    print(f"{len(frames)} frames of {info.prod_line} ({frames[0][1].shape[0]} x {frames[0][1].shape[1]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""heading_hold: an arcnav behaviour written in Python, in its own process.

It votes for the arcs that turn the vehicle towards a compass heading (say,
"keep going east" across open country between waypoints). Each decision
cycle it is sent the local map, with the pose the cycle is expressed in; it
answers with one vote in [-1, 1] per arc, stamped with the cycle's time,
and the arbiter fuses it with the other behaviours' votes at the weight the
configuration gives it. Obstacle avoidance still vetoes what it must: this
behaviour only says where it would like to go.

The same script runs in both places (arcnav_behaviour.py hides how): in
lock-step, started by `arcnav sim`, `sweep` or `replay` from

    [behaviours.external.heading_hold]
    command = ["python3", "examples/python/heading_hold.py", "--heading-deg", "90"]
    [arbiter.weights]
    heading_hold = 0.5

and live beside `arcnav run` with the same configuration, over LCM (LOCAL_MAP
in, ARC_VOTES_HEADING_HOLD out):

    python3 -m pip install lcm                                   # the reference LCM
    lcm-gen -p --ppath examples/python/lcmtypes bus/lcmtypes/*.lcm   # arcnav's types, once
    python3 examples/python/heading_hold.py --heading-deg 90

With [bus.auth] on, give it the same key file (--key-file): its votes then
carry the HMAC-SHA256 trailer bus/src/auth.rs describes.
"""

import argparse
import hashlib
import hmac
import math
import os
import signal
import stat
import struct
import sys
import time

from arcnav_behaviour import Bus, arc_curvatures, behaviour_name

try:
    from arcnav import arc_votes_t, local_map_t
except ImportError:
    sys.exit(
        "heading_hold: arcnav's LCM types are not importable; generate them with\n"
        "  lcm-gen -p --ppath examples/python/lcmtypes bus/lcmtypes/*.lcm\n"
        "(or put a directory holding them on PYTHONPATH)"
    )


def yaw_of(q):
    """Heading (rad, counter-clockwise from +x = east) of a w, x, y, z quaternion."""
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def votes_for(yaw, target, curvatures, lookahead_m):
    """cos of the heading error left after driving lookahead_m along each arc."""
    votes = []
    for k in curvatures:
        error = target - (yaw + k * lookahead_m)
        votes.append(math.cos(math.atan2(math.sin(error), math.cos(error))))
    return votes


class Signer:
    """arcnav's authentication trailer (bus/src/auth.rs)."""

    def __init__(self, path):
        mode = os.stat(path).st_mode
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            sys.exit(f"key file {path}: readable by others (mode {mode & 0o777:o}); chmod 600 {path}")
        self.key = bytes.fromhex("".join(open(path).read().split()))
        if len(self.key) < 32:
            sys.exit(f"key file {path}: a {len(self.key)}-byte key; at least 32 bytes are needed")
        self.last = 0

    def sign(self, channel, message):
        counter = max(time.time_ns() // 1000, self.last + 1)
        self.last = counter
        name = channel.encode()
        tag = hmac.new(
            self.key,
            b"arcnav-auth-v1" + struct.pack(">I", len(name)) + name + message + struct.pack(">Q", counter),
            hashlib.sha256,
        ).digest()
        return message + b"ARA1" + bytes(4) + struct.pack(">Q", counter) + tag


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--heading-deg", type=float, required=True,
                        help="the heading to hold, degrees counter-clockwise from east (+x)")
    parser.add_argument("--name", default=behaviour_name("heading_hold"),
                        help="behaviour name: votes go to ARC_VOTES_<NAME> (default: the name arcnav "
                             "gives in lock-step, else heading_hold)")
    parser.add_argument("--lookahead-m", type=float, default=8.0,
                        help="judge each arc's heading after this distance along it (default 8)")
    parser.add_argument("--arcs", type=int, default=39,
                        help="[arcs] count, live (default 39; in lock-step arcnav gives the arc set)")
    parser.add_argument("--min-radius-m", type=float, default=8.0,
                        help="[arcs] min_radius_m, live (default 8)")
    parser.add_argument("--lcm", default=os.environ.get("LCM_DEFAULT_URL", ""),
                        help="LCM URL (default: $LCM_DEFAULT_URL or LCM's default)")
    parser.add_argument("--key-file", help="[bus.auth] key file: sign the votes (live)")
    args = parser.parse_args()
    if args.arcs < 3 or args.arcs % 2 == 0 or args.min_radius_m <= 0 or args.lookahead_m <= 0:
        sys.exit("--arcs must be odd and at least 3; --min-radius-m and --lookahead-m positive")

    curvatures = arc_curvatures(args.arcs, args.min_radius_m)
    target = math.radians(args.heading_deg)
    channel = "ARC_VOTES_" + args.name.upper()
    bus = Bus(args.lcm)
    signer = Signer(args.key_file) if args.key_file and not bus.lockstep else None
    voted = {"cycles": 0, "undecodable": 0}

    def on_map(_channel, data):
        try:
            snapshot = local_map_t.decode(data)
        except ValueError:
            voted["undecodable"] += 1
            return
        msg = arc_votes_t()
        msg.utime = snapshot.cycle_utime
        msg.behaviour = args.name
        msg.num_arcs = len(curvatures)
        msg.curvature = curvatures
        msg.votes = votes_for(yaw_of(snapshot.orientation), target, curvatures, args.lookahead_m)
        msg.vetoed = [False] * len(curvatures)
        msg.has_speed_vote = False
        msg.speed_vote = 0.0
        msg.arc_speed = [-1.0] * len(curvatures)      # no speed limit of its own
        msg.reverse_clear = [-1.0] * len(curvatures)  # no opinion on backing up
        msg.forward_clear = [-1.0] * len(curvatures)  # nor on creeping forwards
        msg.veto_cause = [0] * len(curvatures)        # it vetoes nothing (NOT_SAID)
        msg.veto_x = [0.0] * len(curvatures)
        msg.veto_y = [0.0] * len(curvatures)
        payload = msg.encode()
        bus.publish(channel, signer.sign(channel, payload) if signer else payload)
        voted["cycles"] += 1

    # With [bus.auth] on, LOCAL_MAP carries a trailer only when configured
    # to: local_map_t.decode reads its fields and ignores what follows.
    bus.subscribe("LOCAL_MAP", on_map)
    running = [True]

    def stop(*_):
        running[0] = False

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    print(f"{args.name}: holding heading {args.heading_deg:.1f}°, voting on {channel}", file=sys.stderr, flush=True)
    last_status = time.monotonic()
    failures = 0
    while running[0]:
        try:
            if not bus.handle(100):
                break  # lock-step: arcnav closed the input
            failures = 0
        except OSError:
            # A signal interrupts the wait (its handler runs right after);
            # an error that persists is not that.
            failures += 1
            if failures >= 10:
                raise
        if time.monotonic() - last_status >= 10.0:
            last_status = time.monotonic()
            print(f"{args.name}: voted on {voted['cycles']} cycles", file=sys.stderr, flush=True)
    print(f"{args.name}: voted on {voted['cycles']} cycles, {voted['undecodable']} undecodable maps",
          file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()

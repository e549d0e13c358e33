#!/usr/bin/env python3
"""An external behaviour that goes wrong on purpose, for arcnav's tests.

    misbehaving.py MODE [CYCLES]

votes straight ahead (a valid vote) for CYCLES cycles (default 3), then:
crash (exits with status 3), hang (stops answering), garbage (writes text
on its standard output), wrong_arcs (votes over 5 arcs), future (stamps its
votes a second ahead), undecodable (sends bytes that are no arc_votes_t).
"""

import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "python"))

from arcnav_behaviour import Bus, arc_curvatures, behaviour_name  # noqa: E402
from arcnav import arc_votes_t, local_map_t  # noqa: E402

mode = sys.argv[1]
good_cycles = int(sys.argv[2]) if len(sys.argv) > 2 else 3
name = behaviour_name("misbehaving")
channel = "ARC_VOTES_" + name.upper()
bus = Bus()
cycles = [0]


def votes(utime, curvatures):
    msg = arc_votes_t()
    msg.utime = utime
    msg.behaviour = name
    msg.num_arcs = len(curvatures)
    msg.curvature = curvatures
    msg.votes = [1.0 - abs(k) * 8.0 for k in curvatures]
    msg.vetoed = [False] * len(curvatures)
    msg.has_speed_vote = False
    msg.speed_vote = 0.0
    msg.arc_speed = [-1.0] * len(curvatures)
    msg.reverse_clear = [-1.0] * len(curvatures)
    msg.forward_clear = [-1.0] * len(curvatures)
    msg.veto_cause = [0] * len(curvatures)
    msg.veto_x = [0.0] * len(curvatures)
    msg.veto_y = [0.0] * len(curvatures)
    return msg.encode()


def on_map(_channel, data):
    utime = local_map_t.decode(data).cycle_utime
    cycles[0] += 1
    arcs = arc_curvatures(39, 8.0)
    if cycles[0] <= good_cycles:
        bus.publish(channel, votes(utime, arcs))
        return
    if cycles[0] == good_cycles + 1:
        print(f"{name}: now going wrong ({mode})", file=sys.stderr, flush=True)
    if mode == "crash":
        sys.exit(3)
    if mode == "hang":
        time.sleep(600)
    if mode == "garbage":
        sys.__stdout__.write("hello world\n")
        sys.__stdout__.flush()
        return
    if mode == "wrong_arcs":
        bus.publish(channel, votes(utime, [k for k in arcs[::8]]))
    elif mode == "future":
        bus.publish(channel, votes(utime + 1_000_000, arcs))
    elif mode == "undecodable":
        bus.publish(channel, b"\x00" * 12)
    else:
        sys.exit(f"unknown mode {mode}")


bus.subscribe("LOCAL_MAP", on_map)
while bus.handle():
    pass

"""arcnav_behaviour: the transport of an arcnav behaviour written in Python.

One script runs in both places a behaviour runs, unchanged:

- live, beside `arcnav run` (or `arcnav node localmap`): over LCM, with the
  reference `lcm` package (LOCAL_MAP in, ARC_VOTES_<NAME> out);
- in lock-step, started by `arcnav sim`, `arcnav sweep` or `arcnav replay`
  from `[behaviours.external.NAME] command`: over its standard input and
  output, one decision cycle at a time (arcnav sets ARCNAV_TRANSPORT=stdio).

`Bus` hides which. Subscribe to the channels you need, publish your votes,
and call `handle()` until it returns False:

    bus = Bus()
    bus.subscribe("LOCAL_MAP", on_map)      # on_map(channel, data) publishes the votes
    while bus.handle(timeout_ms=100):
        pass

In lock-step each cycle sends WAYPOINTS (when the mission changed),
STEERING_COMMAND (when a new command was sent), POSE and last LOCAL_MAP,
each framed as

    u32 big-endian channel length, channel, u32 big-endian payload length, payload

(the payload LCM-encoded, as on the bus), and waits for one `arc_votes_t`
on ARC_VOTES_<NAME> stamped with the map's `cycle_utime`. Standard output
carries only those frames: `print()` goes to standard error there, which
arcnav shows in its log and quotes when the program ends early.

arcnav's types for Python come from `lcm-gen -p --ppath
examples/python/lcmtypes bus/lcmtypes/*.lcm`; this module puts
examples/python/lcmtypes on the import path when it is there.
"""

import os
import struct
import sys

_here = os.path.dirname(os.path.abspath(__file__))
if os.path.isdir(os.path.join(_here, "lcmtypes")):
    sys.path.insert(0, os.path.join(_here, "lcmtypes"))

MAX_CHANNEL = 256
MAX_PAYLOAD = 64 << 20


def lockstep():
    """True when arcnav started this program in lock-step (stdio)."""
    return os.environ.get("ARCNAV_TRANSPORT") == "stdio"


def behaviour_name(default):
    """The behaviour's name: the one arcnav gives in lock-step, else `default`."""
    return os.environ.get("ARCNAV_BEHAVIOUR", default)


def arc_curvatures(count, min_radius_m):
    """The arc set's curvatures, 1/m: arcnav's own in lock-step (it sends them
    in ARCNAV_ARC_CURVATURES), else the set of [arcs] count and min_radius_m."""
    given = os.environ.get("ARCNAV_ARC_CURVATURES")
    if given:
        return [float(k) for k in given.split(",")]
    k_max = 1.0 / min_radius_m
    half = count - 1
    return [k_max * (2 * i - half) / half for i in range(count)]


class _Stdio:
    def __init__(self):
        self._in = sys.stdin.buffer
        self._out = sys.stdout.buffer
        # Standard output carries frames only.
        sys.stdout = sys.stderr

    def _read(self, n):
        data = self._in.read(n)
        if data is None or len(data) < n:
            return None
        return data

    def next(self):
        """The next (channel, payload), or None at the end of the input."""
        head = self._read(4)
        if head is None:
            return None
        (length,) = struct.unpack(">I", head)
        if length > MAX_CHANNEL:
            raise ValueError(f"a frame's channel name of {length} bytes")
        channel = self._read(length)
        size = self._read(4)
        if channel is None or size is None:
            return None
        (length,) = struct.unpack(">I", size)
        if length > MAX_PAYLOAD:
            raise ValueError(f"a frame of {length} bytes")
        payload = self._read(length)
        if payload is None:
            return None
        return channel.decode(), payload

    def publish(self, channel, data):
        name = channel.encode()
        self._out.write(struct.pack(">I", len(name)) + name + struct.pack(">I", len(data)) + data)
        self._out.flush()


class Bus:
    """LCM live, arcnav's standard input and output in lock-step."""

    def __init__(self, lcm_url=""):
        self._handlers = {}
        if lockstep():
            self._stdio = _Stdio()
            self._lcm = None
        else:
            import lcm  # the reference LCM: needed live only

            self._stdio = None
            self._lcm = lcm.LCM(lcm_url) if lcm_url else lcm.LCM()

    @property
    def lockstep(self):
        return self._stdio is not None

    def subscribe(self, channel, handler):
        """handler(channel, data) for each message on `channel`."""
        if self._lcm is not None:
            self._lcm.subscribe(channel, handler)
        else:
            self._handlers.setdefault(channel, []).append(handler)

    def publish(self, channel, data):
        if self._lcm is not None:
            self._lcm.publish(channel, data)
        else:
            self._stdio.publish(channel, data)

    def handle(self, timeout_ms=100):
        """Handles what arrives (live: waits at most timeout_ms; in lock-step:
        the next message). False once arcnav closed the input: time to end."""
        if self._lcm is not None:
            self._lcm.handle_timeout(timeout_ms)
            return True
        frame = self._stdio.next()
        if frame is None:
            return False
        channel, payload = frame
        for handler in self._handlers.get(channel, ()):
            handler(channel, payload)
        return True

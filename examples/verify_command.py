#!/usr/bin/env python3
"""Verify arcnav's authenticated steering commands with nothing but Python.

A vehicle controller that is not written in Rust checks each command the
same way (the wire form is documented in bus/src/auth.rs):

    message || "ARA1" || 4 zero bytes || counter (u64 BE, µs) || tag (32 bytes)
    tag = HMAC-SHA256(key, b"arcnav-auth-v1" || u32 BE len(channel) || channel
                           || message || counter)

and then refuses a counter it has seen, or one too old or too far ahead of
its own clock. This script reads an LCM event log (as `lcm-logger` writes it)
and prints each STEERING_COMMAND as accepted or refused, with why.

    verify_command.py KEY_FILE LOG [--max-age-s 1.0]

KEY_FILE holds the group key in hex, readable by its owner only. Ages are
judged against the log's own timestamps (a live controller uses its clock).
Exit status: 0 when every command verified, 1 when any was refused.
"""

import argparse
import hashlib
import hmac
import os
import stat
import struct
import sys

MAGIC = b"ARA1"
TRAILER = 48
DOMAIN = b"arcnav-auth-v1"
SYNC = 0xEDA1DA01
# steering_command_t after its 8-byte fingerprint: utime, curvature, speed,
# arc_index, vote.
COMMAND = struct.Struct(">qddif")


def read_key(path):
    mode = os.stat(path).st_mode
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        sys.exit(f"key file {path}: readable by others (mode {mode & 0o777:o}); chmod 600 {path}")
    key = bytes.fromhex("".join(open(path).read().split()))
    if len(key) < 32:
        sys.exit(f"key file {path}: a {len(key)}-byte key; at least 32 bytes are needed")
    return key


def events(path):
    data = open(path, "rb").read()
    at = 0
    while at + 28 <= len(data):
        sync, _, timestamp, channel_len, data_len = struct.unpack_from(">IqqII", data, at)
        if sync != SYNC:
            sys.exit(f"{path}: no LCM event at byte {at}")
        start = at + 28
        channel = data[start:start + channel_len].decode()
        yield timestamp, channel, data[start + channel_len:start + channel_len + data_len]
        at = start + channel_len + data_len


def verify(key, channel, data, now_us, max_age_us, seen):
    """The message without its trailer, or the reason it is refused."""
    if len(data) < TRAILER or data[-TRAILER:-TRAILER + 4] != MAGIC:
        return None, "unauthenticated"
    message, trailer = data[:-TRAILER], data[-TRAILER:]
    counter = struct.unpack(">Q", trailer[8:16])[0]
    name = channel.encode()
    expected = hmac.new(
        key,
        DOMAIN + struct.pack(">I", len(name)) + name + message + struct.pack(">Q", counter),
        hashlib.sha256,
    ).digest()
    if trailer[4:8] != bytes(4) or not hmac.compare_digest(expected, trailer[16:]):
        return None, "bad tag"
    if counter + max_age_us < now_us:
        return None, "expired"
    if counter in seen:
        return None, "replayed"
    seen.add(counter)
    return message, None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("key_file")
    parser.add_argument("log")
    parser.add_argument("--max-age-s", type=float, default=1.0)
    args = parser.parse_args()
    key = read_key(args.key_file)
    seen, refused, accepted = set(), 0, 0
    for timestamp, channel, data in events(args.log):
        if channel != "STEERING_COMMAND":
            continue
        message, why = verify(key, channel, data, timestamp, args.max_age_s * 1e6, seen)
        if why:
            refused += 1
            print(f"{timestamp} refused: {why}")
            continue
        accepted += 1
        utime, curvature, speed, arc, vote = COMMAND.unpack_from(message, 8)
        print(f"{timestamp} accepted: curvature {curvature:+.4f} 1/m, speed {speed:.2f} m/s, arc {arc}")
    print(f"{accepted} accepted, {refused} refused")
    return 1 if refused else 0


if __name__ == "__main__":
    sys.exit(main())

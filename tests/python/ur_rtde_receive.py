"""Reads joint positions and controller timestamps with ur_rtde's RTDEReceiveInterface (the
PyPI package ur-rtde), as a UR user's script would, and prints them as one JSON document:
{"samples": [{"timestamp": s, "actual_q": [rad, ...], "robot_mode": n, "safety_mode": n,
"runtime_state": n, "safety_status_bits": n, "tool_accelerometer": [m/s^2, x3]}, ...]}.

The modes, bits and accelerometer lie behind the 64-bit digital I/O fields in ur_rtde's default
recipe, which it decodes with its own type table: they read sensibly only if the server gave
every earlier variable the size ur_rtde expects.

RTDEReceiveInterface always connects to port 30004 of HOST. Each sample comes from a newer data
package than the one before (the timestamp changed), so the samples show the stream advancing.
"""

import argparse
import json
import sys
import time

import rtde_receive


def next_timestamp(receiver, previous, timeout_s):
    """Waits until the receiver holds a data package newer than `previous`."""
    deadline = time.monotonic() + timeout_s
    while True:
        timestamp = receiver.getTimestamp()
        if timestamp != previous:
            return timestamp
        if time.monotonic() > deadline:
            raise TimeoutError(f"no new data package within {timeout_s} s")
        time.sleep(0.001)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("host")
    parser.add_argument("--count", type=int, default=5)
    parser.add_argument("--timeout-s", type=float, default=5.0)
    args = parser.parse_args()

    receiver = rtde_receive.RTDEReceiveInterface(args.host)
    samples = []
    timestamp = None
    try:
        for _ in range(args.count):
            timestamp = next_timestamp(receiver, timestamp, args.timeout_s)
            samples.append(
                {
                    "timestamp": timestamp,
                    "actual_q": receiver.getActualQ(),
                    "robot_mode": receiver.getRobotMode(),
                    "safety_mode": receiver.getSafetyMode(),
                    "runtime_state": receiver.getRuntimeState(),
                    "safety_status_bits": receiver.getSafetyStatusBits(),
                    "tool_accelerometer": receiver.getActualToolAccelerometer(),
                }
            )
    finally:
        receiver.disconnect()
    json.dump({"samples": samples}, sys.stdout)
    print()


if __name__ == "__main__":
    main()

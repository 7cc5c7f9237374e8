#!/usr/bin/env python3
"""Mirror joint states from robot-bridge with pyzmq, speaking the thesis's messages.

    python3 examples/python/mirror_joint_states.py --rep tcp://127.0.0.1:2000 --pub tcp://127.0.0.1:3000 --count 10
    python3 examples/python/mirror_joint_states.py --robot-side IiwaDrive ...   # a KUKA iiwa bridge

Sends the thesis's START instruction, prints COUNT hardware-state samples (one JSON line each
with --json), then sends STOP. Exits 1 if the bridge refuses or goes silent.
"""

import argparse
import json
import sys

import zmq



def instruction(command, robot_side):
    """The thesis's instruction: robot side "ros" for UR, "IiwaDrive" for the KUKA iiwa."""
    return {"header": {"from": "ips", "to": robot_side, "type": "instruction"}, "body": {"command": command, "content": "hwState"}}


def instruct(context, endpoint, message, timeout_ms):
    socket = context.socket(zmq.REQ)
    socket.setsockopt(zmq.LINGER, 0)
    socket.setsockopt(zmq.RCVTIMEO, timeout_ms)
    socket.connect(endpoint)
    # Compact separators: the exact bytes of the thesis's messages.
    socket.send_string(json.dumps(message, separators=(",", ":")))
    reply = json.loads(socket.recv_string())
    socket.close()
    return reply


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rep", default="tcp://127.0.0.1:2000")
    parser.add_argument("--pub", default="tcp://127.0.0.1:3000")
    parser.add_argument("--count", type=int, default=10)
    parser.add_argument("--json", action="store_true", help="print each sample as one JSON line")
    parser.add_argument("--timeout-ms", type=int, default=3000)
    parser.add_argument("--robot-side", default="ros", choices=["ros", "IiwaDrive"], help="who the bridge is in the thesis's headers")
    args = parser.parse_args()

    context = zmq.Context()
    subscriber = context.socket(zmq.SUB)
    subscriber.setsockopt(zmq.LINGER, 0)
    subscriber.setsockopt(zmq.RCVTIMEO, args.timeout_ms)
    subscriber.setsockopt_string(zmq.SUBSCRIBE, "")
    subscriber.connect(args.pub)

    ack = instruct(context, args.rep, instruction("start", args.robot_side), args.timeout_ms)
    if ack["body"]["content"] != "ok":
        print(f"bridge refused start: {ack['body'].get('reason', '?')}", file=sys.stderr)
        return 1
    try:
        for _ in range(args.count):
            state = json.loads(subscriber.recv_string())
            body = state["body"]
            if args.json:
                print(json.dumps({"seq": body["seq"], "controller_time": body["controller_time"], "position": body["position"], "from": state["header"]["from"]}))
            else:
                joints = " ".join(f"{q:+.4f}" for q in body["position"])
                print(f"seq {body['seq']:6d}  t {body['controller_time']:9.3f} s  q [rad] {joints}")
    except zmq.Again:
        print("no hardware state within the timeout", file=sys.stderr)
        return 1
    finally:
        instruct(context, args.rep, instruction("stop", args.robot_side), args.timeout_ms)
    return 0


if __name__ == "__main__":
    sys.exit(main())

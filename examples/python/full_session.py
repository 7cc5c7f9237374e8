#!/usr/bin/env python3
"""A full inspection session against `ips serve`, driving sim-robot to each touch (pyzmq).

    python3 examples/python/full_session.py --service tcp://127.0.0.1:4000 \\
        --sim-control tcp://127.0.0.1:5000 --bridge-pub tcp://127.0.0.1:3000 \\
        --plan examples/step_block_ur10/session.json [--first 0 --count 9] [--align]

For each planned joint vector (the `q` of the plan session's inspections) it tells the
simulator to hold it, waits until the hardware-state stream shows it, and asks the service to
`get` an inspection. With --align it then aligns and prints the pose as one JSON line.
"""

import argparse
import json
import sys
import time

import zmq


def request(socket, body):
    socket.send_string(json.dumps({"header": {"from": "ips", "to": "align", "type": "request"}, "body": body}))
    return json.loads(socket.recv_string())["body"]


def connect(context, kind, endpoint, timeout_ms=10000):
    socket = context.socket(kind)
    socket.setsockopt(zmq.LINGER, 0)
    socket.setsockopt(zmq.RCVTIMEO, timeout_ms)
    socket.connect(endpoint)
    return socket


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--service", default="tcp://127.0.0.1:4000")
    parser.add_argument("--sim-control", default="tcp://127.0.0.1:5000")
    parser.add_argument("--bridge-pub", default="tcp://127.0.0.1:3000")
    parser.add_argument("--plan", required=True, help="session file whose inspections' q are the touches")
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--count", type=int, default=None)
    parser.add_argument("--align", action="store_true")
    args = parser.parse_args()

    with open(args.plan) as plan_file:
        plan = [inspection["q"] for inspection in json.load(plan_file)["inspections"]]
    last = len(plan) if args.count is None else args.first + args.count
    context = zmq.Context()
    service = connect(context, zmq.REQ, args.service)
    control = connect(context, zmq.REQ, args.sim_control)
    states = connect(context, zmq.SUB, args.bridge_pub)
    states.setsockopt_string(zmq.SUBSCRIBE, "")

    deadline = time.monotonic() + 20
    while True:
        reply = request(service, {"command": "start"})
        if reply["ok"]:
            break
        if time.monotonic() > deadline:
            print(f"cannot start mirroring: {reply.get('reason')}", file=sys.stderr)
            return 1
        time.sleep(0.05)

    for q in plan[args.first:last]:
        control.send_string(json.dumps({"command": "motion", "motion": {"kind": "hold", "q": q}}))
        if not json.loads(control.recv_string())["ok"]:
            return 1
        seen_after = None
        while seen_after is None or seen_after < 2:
            position = json.loads(states.recv_string())["body"]["position"]
            at_touch = all(abs(a - b) < 1e-9 for a, b in zip(position, q))
            if seen_after is not None:
                seen_after += 1
            elif at_touch:
                seen_after = 0
        reply = request(service, {"command": "get"})
        if not reply["ok"]:
            print(f"get refused: {reply.get('reason')}", file=sys.stderr)
            return 1
        print(json.dumps({"inspection": reply["data"]["id"]}))

    if args.align:
        reply = request(service, {"command": "align"})
        if not reply["ok"]:
            print(f"align failed: {reply.get('reason')}", file=sys.stderr)
            return 1
        print(json.dumps({"pose": reply["data"]["pose"], "rms": reply["data"]["rms"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

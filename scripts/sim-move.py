#!/usr/bin/env python3
"""Stands in for your hands on the simulated robot (docs/your-cell.md, the simulator track).

On a real cell you move the arm by freedrive or hand guiding and then take the touch with
`ips get`. On sim-robot nobody can push the arm, so this script does it through sim-robot's
control socket: it holds the arm at the given joints and returns once the bridge's hardware-state
stream shows the arm there, so that an `ips get` right after it captures the new pose. It can also
give the simulated encoders an error nobody declared (sim-robot's `effects` command), which the
diagnosis should then find.

    sim-move.py --control tcp://127.0.0.1:5000 --pub tcp://127.0.0.1:3000 --q 0.1,-1.2,1.4,-1.8,-1.57,0
    sim-move.py --control tcp://127.0.0.1:5000 --effects '{"joint_offsets": [0, 0, 0.0015, 0, 0, 0]}'
    sim-move.py --control ... --pub ... --plan plan.json --touch 3      (the planned contact joints)

Needs pyzmq (scripts/python-env.sh installs it into .venv).
"""
import argparse
import json
import sys
import time

import zmq

TIMEOUT_MS = 10_000
#: Joint distance under which the stream counts as showing the target (an encoder error the
#: effects add is a few mrad at most), rad.
AT_TARGET_RAD = 0.01
#: Samples to wait after the first at the target: the alignment service's own subscription has
#: seen the pose by then.
SETTLE_SAMPLES = 3


def fail(message):
    print(f"sim-move: {message}", file=sys.stderr)
    sys.exit(2)


def control(context, endpoint, request):
    socket = context.socket(zmq.REQ)
    socket.setsockopt(zmq.LINGER, 0)
    socket.setsockopt(zmq.RCVTIMEO, TIMEOUT_MS)
    socket.connect(endpoint)
    socket.send_string(json.dumps(request))
    try:
        reply = json.loads(socket.recv())
    except zmq.Again:
        fail(f"no reply from sim-robot's control socket {endpoint}")
    if not reply.get("ok"):
        fail(f"sim-robot refused {request['command']}: {reply.get('reason')}")
    return reply


def wait_until_streamed(context, endpoint, q):
    socket = context.socket(zmq.SUB)
    socket.setsockopt(zmq.LINGER, 0)
    socket.setsockopt(zmq.RCVTIMEO, TIMEOUT_MS)
    socket.setsockopt(zmq.SUBSCRIBE, b"")
    socket.connect(endpoint)
    seen = None
    deadline = time.monotonic() + TIMEOUT_MS / 1000
    while seen is None or seen < SETTLE_SAMPLES:
        if time.monotonic() > deadline:
            fail(f"the bridge at {endpoint} never showed the arm at the target")
        try:
            state = json.loads(socket.recv())
        except zmq.Again:
            fail(f"no hardware state from the bridge at {endpoint}")
        position = state.get("body", {}).get("position", [])
        there = len(position) == len(q) and max(abs(a - b) for a, b in zip(position, q)) < AT_TARGET_RAD
        if seen is not None:
            seen += 1
        elif there:
            seen = 0


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--control", required=True, help="sim-robot's control endpoint")
    parser.add_argument("--pub", help="robot-bridge's hardware-state endpoint (to wait for the move)")
    parser.add_argument("--q", help="joint values, rad, comma-separated")
    parser.add_argument("--plan", help="an `ips plan --json` document")
    parser.add_argument("--touch", help="the planned touch's id (with --plan): its contact joints")
    parser.add_argument("--effects", help="sim-robot effects as JSON (undeclared encoder errors)")
    args = parser.parse_args()
    context = zmq.Context()
    if args.effects:
        try:
            effects = json.loads(args.effects)
        except json.JSONDecodeError as error:
            fail(f"--effects is not JSON: {error}")
        control(context, args.control, {"command": "effects", **effects})
    if args.plan:
        touches = json.load(open(args.plan))["touches"]
        chosen = [t for t in touches if t["id"] == args.touch]
        if not chosen or "q_contact" not in chosen[0]:
            fail(f"the plan has no touch '{args.touch}' with joints")
        q = chosen[0]["q_contact"]
    elif args.q:
        try:
            q = [float(v) for v in args.q.split(",")]
        except ValueError:
            fail("--q must be comma-separated numbers (rad)")
    else:
        return
    if not args.pub:
        fail("--pub is needed to wait for the move")
    control(context, args.control, {"command": "motion", "motion": {"kind": "hold", "q": q}})
    wait_until_streamed(context, args.pub, q)


if __name__ == "__main__":
    main()

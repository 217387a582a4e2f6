"""A stand-in for a robot computer in the security tests, run as its own process:
``python tests/acl_probe.py CONFIG.json5 --ns NS --claim I --own J``. It opens a
session with the given Zenoh configuration (exit 3 if it cannot), then, round after
round, publishes well-formed commands and states and a liveliness token for robot
``--claim`` (someone else's keys) and then for robot ``--own`` (its own), so that
when the last own message has arrived every claimed one would have too. It begins
once a subscriber (the test's observer) has reached its own publishers: the tokens
are declared before that, so they reach the observer before any message does."""

from __future__ import annotations

import argparse
import sys
import time

import zenoh

from wire import AgentState, Cmd, Keys, encode

MATCH_TIMEOUT_S = 10.0


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("config")
    p.add_argument("--ns", required=True)
    p.add_argument("--claim", type=int, required=True, help="robot whose keys it tries")
    p.add_argument("--own", type=int, help="robot whose keys are its own (control)")
    p.add_argument("--rounds", type=int, default=20)
    a = p.parse_args()
    keys = Keys(a.ns)
    try:
        session = zenoh.open(zenoh.Config.from_file(a.config))
    except Exception as exc:
        print(f"cannot open: {exc}", flush=True)
        return 3
    print("opened", flush=True)
    ids = [a.claim] + ([a.own] if a.own is not None else [])
    tokens = [session.liveliness().declare_token(keys.alive(i)) for i in ids]
    block = zenoh.CongestionControl.BLOCK  # every round is counted: none may be dropped
    pubs = {i: (session.declare_publisher(keys.cmd(i), congestion_control=block),
                session.declare_publisher(keys.state(i), congestion_control=block))
            for i in ids}
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while not all(p.matching_status.matching for p in pubs[ids[-1]]):
        if time.monotonic() > deadline:
            print(f"no subscriber after {MATCH_TIMEOUT_S:g} s", flush=True)
            return 4
        time.sleep(0.01)
    for k in range(a.rounds):
        for i in ids:  # the claimed robot's first, the own last
            cmd = Cmd(t=k * 0.1, k=k, robot=i, v=0.5, omega=1.0)
            state = AgentState(t=k * 0.1, k=k, robot=i, lo=0.0, hi=6.0, phase=0.0,
                               phase_des=0.0, workload=1.8, depth_avg=0.3, direction=1,
                               lower=-1, upper=-1, edge_lo=0.0, edge_hi=6.0, dropped=0)
            pubs[i][0].put(encode(cmd))
            pubs[i][1].put(encode(state))
    for t in tokens:
        t.undeclare()
    session.close()
    print("done", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A process that lies on a run's bus (issue 19, items 1-3), for the tests: well-formed
messages that cannot be true. ``python -m tests.forger --ns NS --connect EP --at K``
waits for the world's tick K, then, as robot 1, publishes a state of tick 10^9, states
of the next ticks claiming [0, 5.9] m, one with end depths of 1.7e307 m and one that
moves the boundary it shares with robot 2 1.5 m, beyond the law's reach; a world tick
with done = true; and holds a liveliness token of robot 7 (a team of three) until it
is ended."""

from __future__ import annotations

import argparse
import dataclasses
import threading

from wire import AgentState, Keys, Tick, decode, encode
from wire.session import SessionOptions, open_session


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--ns", required=True)
    p.add_argument("--connect", required=True)
    p.add_argument("--at", type=int, required=True, help="the world's tick to lie at")
    args = p.parse_args()
    keys = Keys(args.ns)
    opts = SessionOptions(ns=args.ns, mode="client", connect=(args.connect,), multicast=False)
    with open_session(opts) as session:
        now = threading.Event()
        heard: dict[str, object] = {}

        def on_tick(sample) -> None:  # noqa: ANN001
            tick = decode(Tick, sample.payload.to_bytes())
            if tick.k >= args.at and not now.is_set():
                heard["tick"] = tick
                now.set()

        def on_state(sample) -> None:  # noqa: ANN001
            heard["state"] = decode(AgentState, sample.payload.to_bytes())

        subs = [session.declare_subscriber(keys.world_tick(), on_tick),
                session.declare_subscriber(keys.state(1), on_state)]
        now.wait()
        tick = heard["tick"]
        real = heard["state"]
        assert isinstance(tick, Tick) and isinstance(real, AgentState)
        k = tick.k
        put = session.put
        put(keys.state(1), encode(dataclasses.replace(real, k=10**9, t=1e8)))
        for j in range(2, 7):
            put(keys.state(1), encode(dataclasses.replace(
                real, k=k + j, t=(k + j) * 0.1, lo=0.0, hi=5.9,
                workload=real.depth_avg * 5.9)))
        put(keys.state(1), encode(dataclasses.replace(
            real, k=k + 1, t=(k + 1) * 0.1, end_bins=[20], end_depths=[1.7e307])))
        put(keys.state(1), encode(dataclasses.replace(
            real, k=k + 3, t=(k + 3) * 0.1, hi=real.hi + 1.5,
            workload=real.depth_avg * (real.hi + 1.5 - real.lo))))
        put(keys.world_tick(), encode(dataclasses.replace(tick, k=k + 2, t=(k + 2) * 0.1,
                                                          done=True)))
        token = session.liveliness().declare_token(keys.alive(7))
        print("lied", flush=True)
        threading.Event().wait()  # until the test ends us
        token.undeclare()
        for sub in subs:
            sub.undeclare()


if __name__ == "__main__":
    main()

"""A process that lies on a ring's bus (issue 18), for the tests: well-formed messages
that cannot be true of a ring round a closed edge. ``python -m tests.ring_forger --ns NS
--connect EP --at K`` waits for the world's tick K, then, as robot 1 of the ring, sends
states of the next ticks: its arc a whole turn on (plausible, but a second state of its
tick that moves its boundaries a turn), its upper boundary half a turn on, a bin of its
ends across the ring and an open edge's state; and a WorldInfo whose contour is the
world's grown by 1 %. It prints "lied" and waits to be ended."""

from __future__ import annotations

import argparse
import dataclasses
import threading

from wire import AgentState, Keys, Tick, WorldInfo, decode, encode
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
            if tick.k >= args.at and "info" in heard and not now.is_set():
                heard["tick"] = tick
                now.set()

        def on_state(sample) -> None:  # noqa: ANN001
            heard["state"] = decode(AgentState, sample.payload.to_bytes())

        def on_info(sample) -> None:  # noqa: ANN001
            heard["info"] = decode(WorldInfo, sample.payload.to_bytes())

        subs = [session.declare_subscriber(keys.world_tick(), on_tick),
                session.declare_subscriber(keys.state(1), on_state),
                session.declare_subscriber(keys.world_info(), on_info)]
        now.wait()
        tick, real, info = heard["tick"], heard["state"], heard["info"]
        assert isinstance(tick, Tick) and isinstance(real, AgentState)
        assert isinstance(info, WorldInfo) and info.closed
        k, length = tick.k, real.edge_hi - real.edge_lo
        put = session.put

        def lie(j: int, **fields: object) -> None:
            forged = dataclasses.replace(real, k=k + j, t=(k + j) * 0.1, **fields)
            put(keys.state(1), encode(forged))

        lie(2, lo=real.lo + length, hi=real.hi + length)
        hi = real.hi + 0.5 * length
        lie(3, hi=hi, workload=real.depth_avg * (hi - real.lo))
        across = 0.5 * (real.lo + real.hi) + 0.5 * length  # the far side of the ring
        lie(4, end_bins=[int(across / 0.1)], end_depths=[0.5])
        lie(5, closed=False, lo=0.0, hi=min(real.hi - real.lo, 0.9 * length),
            workload=real.depth_avg * min(real.hi - real.lo, 0.9 * length))
        put(keys.world_info(), encode(dataclasses.replace(
            info, contour=[1.01 * v for v in info.contour])))
        print("lied", flush=True)
        threading.Event().wait()  # until the test ends us
        for sub in subs:
            sub.undeclare()


if __name__ == "__main__":
    main()

"""A process that lies on a ring's bus (issue 18), for the tests: well-formed messages
that cannot be true of a ring round a closed edge. ``python -m tests.ring_forger --ns NS
--connect EP --at K`` waits for the world's tick K, then, as robot 1 of the ring, sends
states of the next ticks: its arc with both ends a quarter of a turn out, a bin of its
ends across the ring and an open edge's state; and a WorldInfo whose contour is the
world's grown by 1 %. It prints "lied" and waits to be ended."""

from __future__ import annotations

import dataclasses
import threading

from tests.forger import forger_args, hear_until
from wire import AgentState, Tick, WorldInfo, encode
from wire.session import open_session


def main() -> None:
    args, keys, opts = forger_args()
    with open_session(opts) as session:
        heard, subs = hear_until(session, keys, args.at, info=True)
        tick, real, info = heard["tick"], heard["state"], heard["info"]
        assert isinstance(tick, Tick) and isinstance(real, AgentState)
        assert isinstance(info, WorldInfo) and info.closed
        k, length = tick.k, real.edge_hi - real.edge_lo
        put = session.put

        def lie(j: int, **fields: object) -> None:
            forged = dataclasses.replace(real, k=k + j, t=(k + j) * 0.1, **fields)
            put(keys.state(1), encode(forged))

        # both ends a quarter of a turn out: beyond the law's reach for both neighbours
        # (a lie only one of them could check would be a second plausible state of its
        # tick to the other, which may act on it before the real one comes)
        lo, hi = real.lo - 0.25 * length, real.hi + 0.25 * length
        lie(2, lo=lo, hi=hi, workload=real.depth_avg * (hi - lo))
        across = 0.5 * (real.lo + real.hi) + 0.5 * length  # the far side of the ring
        lie(3, end_bins=[int(across / 0.1)], end_depths=[0.5])
        lie(4, closed=False, lo=0.0, hi=min(real.hi - real.lo, 0.9 * length),
            workload=real.depth_avg * min(real.hi - real.lo, 0.9 * length))
        put(keys.world_info(), encode(dataclasses.replace(
            info, contour=[1.01 * v for v in info.contour])))
        print("lied", flush=True)
        threading.Event().wait()  # until the test ends us
        for sub in subs:
            sub.undeclare()


if __name__ == "__main__":
    main()

"""A process that lies on a run's bus (issue 19, items 1-3), for the tests: well-formed
messages that cannot be true. ``python -m tests.forger --ns NS --connect EP --at K``
waits for the world's tick K, then, as robot 1, publishes a state of tick 10^9, states
of the next ticks claiming [0.01, 5.9] m, one with end depths of 1.7e307 m and one that
moves both its boundaries 1.5 m out, beyond the law's reach; a world tick with done =
true; it tells these lies again at each of the next ticks it hears (``ROUNDS`` in
all), and holds a liveliness token of robot 7 (a team of three) until it is ended.

Every lie is one both of robot 1's neighbours can refuse. A state that moved only the
boundary robot 1 shares with robot 2 is plausible to robot 0, which cannot judge that
boundary, and when it comes before the real state robot 0 acts on it for a tick (the
README's "Forged states": on an open bus, without the fleet's access control)."""

from __future__ import annotations

import argparse
import dataclasses
import threading
from typing import Any

from wire import AgentState, Keys, Tick, WorldInfo, decode, encode
from wire.session import SessionOptions, open_session


def forger_args() -> tuple[argparse.Namespace, Keys, SessionOptions]:
    """A forger's command line (``--ns``, ``--connect``, ``--at K``), its namespace's
    keys and its session: a client of the run's router, multicast off."""
    p = argparse.ArgumentParser()
    p.add_argument("--ns", required=True)
    p.add_argument("--connect", required=True)
    p.add_argument("--at", type=int, required=True, help="the world's tick to lie at")
    args = p.parse_args()
    opts = SessionOptions(ns=args.ns, mode="client", connect=(args.connect,), multicast=False)
    return args, Keys(args.ns), opts


def hear_until(session: Any, keys: Keys, at: int, info: bool = False
               ) -> tuple[dict[str, Any], list[Any]]:
    """Listen to the world's ticks and robot 1's states (and, with ``info``, the world's
    WorldInfo) until the world's tick ``at`` has come with them; what was heard, by
    "tick", "state" (the latest) and "info", and the subscribers."""
    now = threading.Event()
    heard: dict[str, Any] = {}

    def on_tick(sample: Any) -> None:
        tick = decode(Tick, sample.payload.to_bytes())
        if tick.k >= at and (not info or "info" in heard) and not now.is_set():
            heard["tick"] = tick
            now.set()

    def on_state(sample: Any) -> None:
        heard["state"] = decode(AgentState, sample.payload.to_bytes())

    def on_info(sample: Any) -> None:
        heard["info"] = decode(WorldInfo, sample.payload.to_bytes())

    subs = [session.declare_subscriber(keys.world_tick(), on_tick),
            session.declare_subscriber(keys.state(1), on_state)]
    if info:
        subs.append(session.declare_subscriber(keys.world_info(), on_info))
    now.wait()
    return heard, subs


ROUNDS = 20  # the lies are told again at each of this many world ticks heard


def lie(put: Any, keys: Keys, tick: Tick, real: AgentState, first: bool) -> None:
    """One round of lies, for the ticks after ``tick``, as robot 1 (``real``: its
    latest state heard). Each is one both of robot 1's neighbours can refuse. After the
    first round the [0.01, 5.9] m claims are for the one tick no round has claimed yet:
    an agent parks at most 4 unlike copies of a neighbour's coming tick, and a fifth
    copy of a tick would be refused, the real state too (the README's "Forged
    states")."""
    k = tick.k
    put(keys.state(1), encode(dataclasses.replace(real, k=10**9, t=1e8)))
    for j in range(2, 7) if first else (6,):
        # not from 0 exactly: the edge's end is what the law claims for a robot that
        # lost sight of its lower neighbour, which robot 0 takes when robot 1's state of
        # the tick before has not come yet (the README's "Forged states")
        put(keys.state(1), encode(dataclasses.replace(
            real, k=k + j, t=(k + j) * 0.1, lo=0.01, hi=5.9,
            workload=real.depth_avg * 5.89)))
    put(keys.state(1), encode(dataclasses.replace(
        real, k=k + 1, t=(k + 1) * 0.1, end_bins=[20], end_depths=[1.7e307])))
    put(keys.state(1), encode(dataclasses.replace(
        real, k=k + 3, t=(k + 3) * 0.1, lo=real.lo - 1.5, hi=real.hi + 1.5,
        workload=real.depth_avg * (real.hi - real.lo + 3.0))))
    put(keys.world_tick(), encode(dataclasses.replace(tick, k=k + 2, t=(k + 2) * 0.1,
                                                      done=True)))


def main() -> None:
    args, keys, opts = forger_args()
    with open_session(opts) as session:
        heard, subs = hear_until(session, keys, args.at)
        first = heard["tick"]
        assert isinstance(first, Tick) and isinstance(heard["state"], AgentState)
        # Lies are judged only within a few ticks of each agent's own, and the lockstep
        # runs hundreds of ticks a second: on a loaded machine this process may hear a
        # tick late and lie for ticks already past (dropped unjudged, not counted). So
        # it lies again, from Zenoh's thread the moment each of the next ticks comes.
        rounds = threading.Semaphore(ROUNDS - 1)
        done = threading.Event()

        def on_tick(sample: Any) -> None:
            tick = decode(Tick, sample.payload.to_bytes())
            if done.is_set() or tick.done:
                return
            if not rounds.acquire(blocking=False):
                done.set()
                return
            lie(session.put, keys, tick, heard["state"], first=False)

        lie(session.put, keys, first, heard["state"], first=True)
        subs.append(session.declare_subscriber(keys.world_tick(), on_tick))
        token = session.liveliness().declare_token(keys.alive(7))
        print("lied", flush=True)
        threading.Event().wait()  # until the test ends us
        token.undeclare()
        for sub in subs:
            sub.undeclare()


if __name__ == "__main__":
    main()

"""The team's speed against the bus's ceiling, side by side, for each team size.

The ceiling is a bare lockstep of the team's shape: one world-like process and N
agent-like processes, each its own OS process, linked as ``btrack sim`` links them
(``--agents``): agents as peers of the world, or as clients of a router (a bare
``btrack router``, where the team's router is its recorder) that forwards every message
between them and the world, a peer of it.
Every tick the world puts each agent its Sense, then the team's Truth; each agent,
once it has its Sense of tick k and its two neighbours' states of tick k-1, puts its
state and its command; the world, once it has every command, puts the Tick. The
messages are the wire's own types, of the sizes the team sends (``wire.encode`` and
``wire.decode``, checks included), but nothing else runs: no controller, no
membership, no recorder, no launcher. The team is ``btrack sim --localization truth``
on the same number of ticks. Both are timed from the world's first tick to its last.

    .venv/bin/python bench/lockstep.py [--robots 3 10 30 50] [--duration 30] [--repeat 1]
        [--agents auto|peer|client]

Prints, per team size, the ceiling's and the team's ticks per wall second, their
speed-ups at 10 Hz control and the ratio team / ceiling (the issue's goal: 50 % or
more at 3 robots, 40 % or more up to 50). A shared 2-core machine drifts by a third
within an hour, so each size's ceiling is measured just before its team.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import queue
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import zenoh  # noqa: E402
from decode import SAMPLES  # noqa: E402
from speed import team_run  # noqa: E402

from deploy.launcher import CLIENT_AGENTS_FROM  # noqa: E402
from deploy.procs import Child, ProcessGroup, free_port, wait_listening  # noqa: E402
from wire import AgentState, Cmd, Keys, Sense, Tick, Truth, decode, encode  # noqa: E402
from wire.session import (  # noqa: E402
    SessionOptions,
    declare_publisher,
    loopback_options,
    open_session,
)

DT_S = 0.1  # the team's control period: a speed-up is ticks/s times this
# A long straight edge with room for 50 robots at the design's 0.6 m each (and 200 at
# the controller's 0.15 m minimum), so that every size runs on the same map.
DEFAULT_MAP = "procedural:1,length=30,edge=straight,amplitude=0,algae=steps"
CMD_TIMEOUT_S = 10.0  # a bare agent this late has died: the bench fails, not waits
SETTLE_S = 1.0  # as the world's --settle: subscriptions reach their publishers


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text}")
    return value


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number above 0, got {text}")
    return value


def team_size(text: str) -> int:
    value = positive_int(text)
    if value > 100:  # btrack sim's own limit
        raise argparse.ArgumentTypeError(f"at most 100 robots, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], epilog="Run from the repository's root.")
    p.add_argument("--robots", type=team_size, nargs="+", default=[3, 10, 30, 50],
                   help="team sizes (default 3 10 30 50)")
    p.add_argument("--duration", type=positive_float, default=30.0,
                   help="simulated seconds of each run, ceiling and team (default 30: "
                   "300 ticks)")
    p.add_argument("--repeat", type=positive_int, default=1,
                   help="ceiling-then-team pairs per size (default 1)")
    p.add_argument("--map", default=DEFAULT_MAP, help="the team's map (default: a 30 m "
                   "straight procedural edge, room for every size)")
    p.add_argument("--agents", choices=("auto", "peer", "client"), default="auto",
                   help="the agents' links, ceiling and team alike, as btrack sim's "
                   f"--agents (default auto: clients of the router from {CLIENT_AGENTS_FROM} "
                   "robots on)")
    p.add_argument("--role", choices=["world", "agent"], help=argparse.SUPPRESS)
    p.add_argument("--client", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--id", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--ns", help=argparse.SUPPRESS)
    p.add_argument("--port", type=int, help=argparse.SUPPRESS)
    return p


# the bare processes -----------------------------------------------------------------
def bare_world(ns: str, port: int, n: int, ticks: int, routed: bool) -> dict[str, Any]:
    """The world's side: Sense to each agent and the Truth, every command, the Tick. It
    listens on ``port`` for its peers, or (``routed``) is a peer of the router there."""
    keys = Keys(ns)
    opts = loopback_options(ns, port) if routed else SessionOptions(
        ns=ns, mode="peer", listen=(f"tcp/127.0.0.1:{port}",), multicast=False)
    inbox: queue.SimpleQueue[bytes] = queue.SimpleQueue()
    alive: set[str] = set()
    all_alive = threading.Event()

    def on_alive(sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            alive.add(str(sample.key_expr))
            if len(alive) >= n:
                all_alive.set()

    with open_session(opts) as session:
        pub_sense = [declare_publisher(session, keys.sense(i)) for i in range(n)]
        pub_truth = declare_publisher(session, keys.truth())
        pub_tick = declare_publisher(session, keys.world_tick())
        subs = [session.declare_subscriber(keys.cmd("*"),
                                           lambda s: inbox.put(s.payload.to_bytes())),
                session.liveliness().declare_subscriber(keys.alive("*"), on_alive,
                                                        history=True)]
        if not all_alive.wait(60.0):
            raise SystemExit(f"bare world: {len(alive)} of {n} agents alive after 60 s")
        time.sleep(SETTLE_S)
        sense = SAMPLES["Sense"]
        assert isinstance(sense, Sense)
        poses = [(1.0 + 0.5 * i, -1.0, 1.5707) for i in range(n)]
        began = time.monotonic()
        for k in range(ticks):
            t = k * DT_S
            for i in range(n):
                pub_sense[i].put(encode(dataclasses.replace(sense, t=t, k=k, robot=i)))
            pub_truth.put(encode(Truth.of_team(t, k, poses)))
            pending = set(range(n))
            tick_began = time.monotonic()
            while pending:
                try:
                    cmd = decode(Cmd, inbox.get(timeout=CMD_TIMEOUT_S))
                except queue.Empty:
                    raise SystemExit(f"bare world: no command from {sorted(pending)} at "
                                     f"tick {k}") from None
                if cmd.k == k:
                    pending.discard(cmd.robot)
            waited_ms = 1000.0 * (time.monotonic() - tick_began)
            pub_tick.put(encode(Tick(t, k, list(range(n)), waited_ms, k == ticks - 1,
                                     time.time_ns())))
        wall = time.monotonic() - began
        del subs
    return {"ticks": ticks, "wall_s": round(wall, 3)}


def bare_agent(ns: str, port: int, robot: int, n: int, client: bool) -> None:
    """An agent's side: its Sense and its neighbours' states in, its state and command
    out; until SIGTERM. A peer of the process on ``port``, or its client."""
    keys = Keys(ns)
    inbox: queue.SimpleQueue[tuple[str, bytes]] = queue.SimpleQueue()
    neighbours = [r for r in (robot - 1, robot + 1) if 0 <= r < n]
    stop = threading.Event()

    def on_sigterm(*_: object) -> None:
        stop.set()
        inbox.put(("stop", b""))

    signal.signal(signal.SIGTERM, on_sigterm)
    opts = SessionOptions(ns=ns, mode="client", connect=(f"tcp/127.0.0.1:{port}",),
                          multicast=False) if client else loopback_options(ns, port)
    with open_session(opts) as session:
        pub_state = declare_publisher(session, keys.state(robot))
        pub_cmd = declare_publisher(session, keys.cmd(robot))
        subs = [session.declare_subscriber(keys.sense(robot),
                                           lambda s: inbox.put(("sense", s.payload.to_bytes())))]
        subs += [session.declare_subscriber(
            keys.state(r), lambda s: inbox.put(("state", s.payload.to_bytes())))
            for r in neighbours]
        token = session.liveliness().declare_token(keys.alive(robot))
        senses: dict[int, Sense] = {}
        heard: dict[int, set[int]] = {}  # tick -> neighbours whose state of it came
        sample = SAMPLES["AgentState"]
        assert isinstance(sample, AgentState)
        state = dataclasses.replace(sample, robot=robot)
        k = 0
        while not stop.is_set():
            kind, payload = inbox.get()
            if kind == "sense":
                msg = decode(Sense, payload)
                senses[msg.k] = msg
            elif kind == "state":
                other = decode(AgentState, payload)
                heard.setdefault(other.k, set()).add(other.robot)
            while k in senses and (k == 0 or len(heard.get(k - 1, ())) == len(neighbours)):
                sense = senses.pop(k)
                heard.pop(k - 1, None)
                pub_state.put(encode(dataclasses.replace(state, t=sense.t, k=k)))
                pub_cmd.put(encode(Cmd(sense.t, k, robot, 0.1, 0.0)))
                k += 1
        token.undeclare()
        del subs


def ceiling(n: int, ticks: int, client: bool) -> dict[str, Any]:
    """One bare lockstep of n agents for ``ticks`` ticks: the world's summary. With
    ``client`` the agents are clients of a router the world is a peer of."""
    port, ns = free_port(), f"bench/lockstep-{uuid.uuid4().hex[:8]}"
    me = [sys.executable, str(Path(__file__).resolve()), "--ns", ns, "--port", str(port),
          *(["--client"] if client else [])]
    with tempfile.TemporaryDirectory() as tmp:
        out, err = Path(tmp) / "world.out", Path(tmp) / "world.log"
        routers = ProcessGroup(Path(tmp) / "logs")
        procs: list[subprocess.Popen[bytes]] = []
        try:
            if client:
                hub = f"tcp/127.0.0.1:{port}"
                router = routers.start("router", ["router", "--listen", hub, "--ns", ns,
                                                  "--no-multicast"])
                if not wait_listening(port, router, 30.0):
                    raise SystemExit(f"bench: the router did not listen:\n{router.log_tail()}")
            with open(out, "wb") as o, open(err, "wb") as e:
                world = subprocess.Popen([*me, "--role", "world", "--robots", str(n),
                                          "--duration", str(ticks * DT_S)],
                                         stdin=subprocess.DEVNULL, stdout=o, stderr=e)
            procs.append(world)
            if not client and not wait_listening(port, Child("world", world, err, out), 30.0):
                raise SystemExit(f"bench: the bare world did not listen:\n{err.read_text()}")
            for i in range(n):
                procs.append(subprocess.Popen([*me, "--role", "agent", "--id", str(i),
                                               "--robots", str(n)], stdin=subprocess.DEVNULL,
                                              stdout=subprocess.DEVNULL))
            if world.wait() != 0:
                raise SystemExit(f"bench: the bare world failed:\n{err.read_text()[-2000:]}")
            summary: dict[str, Any] = json.loads(out.read_text().strip().splitlines()[-1])
            return summary
        finally:
            for proc in procs:  # each by its own pid
                if proc.poll() is None:
                    proc.terminate()
            for proc in procs:
                try:
                    proc.wait(5.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            routers.stop_all()


# side by side -----------------------------------------------------------------------
def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    ticks = round(args.duration / DT_S)
    if args.role == "world":
        print(json.dumps(bare_world(args.ns, args.port, args.robots[0], ticks, args.client)),
              flush=True)
        return 0
    if args.role == "agent":
        bare_agent(args.ns, args.port, args.id, args.robots[0], args.client)
        return 0
    print(f"bench: {ticks} ticks a run, ceiling then team, {args.repeat} pair(s) a size; "
          f"load {load()}", flush=True)
    rows = []
    for n in args.robots:
        mode = args.agents if args.agents != "auto" else (
            "client" if n >= CLIENT_AGENTS_FROM else "peer")
        bare, team = [], []
        for r in range(args.repeat):
            print(f"bench: {n} robots ({mode}s), pair {r + 1}: bare lockstep ...", flush=True)
            b = ceiling(n, ticks, mode == "client")
            bare.append(b["ticks"] / b["wall_s"])
            print(f"bench: {n} robots, pair {r + 1}: {bare[-1]:.0f} ticks/s; team ...",
                  flush=True)
            world, _ = team_run(n, args.duration, args.map, "truth", ["--agents", mode])
            team.append(world["ticks"] / world["wall_s"])
            print(f"bench: {n} robots, pair {r + 1}: {team[-1]:.0f} ticks/s; load {load()}",
                  flush=True)
        rows.append((n, mode, statistics.median(bare), statistics.median(team),
                     statistics.median(t / b for t, b in zip(team, bare, strict=True))))
    print(f"\nload average at the end: {load()}")
    print("| robots | agents | ceiling ticks/s | ceiling speed-up | team ticks/s "
          "| team speed-up | team / ceiling |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for n, mode, b, t, ratio in rows:
        print(f"| {n} | {mode}s | {b:.0f} | {b * DT_S:.1f}x | {t:.0f} | {t * DT_S:.1f}x "
              f"| {100 * ratio:.0f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

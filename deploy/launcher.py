"""``btrack sim``: a simulated team on this machine, every part its own OS process.

It starts the recorder, N agents, the localizer (``--localization pf``) and the
world (each a subprocess speaking Zenoh on loopback under a fresh run namespace),
shows progress while the world runs, ends every process it started (on finish, on
error and on Ctrl-C) and writes the report from the recording.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from agent import config as agent_config
from agent.controller import Gains
from agent.phase import wrap_pi
from agent.stability import check_gains
from deploy import faults
from deploy.procs import (
    AGENT_FLAGS,
    ODOM_FLAGS,
    Child,
    ProcessGroup,
    bindable,
    forward_flags,
    free_port,
    non_negative,
    own_faults,
    stop_interrupted,
    stop_on_sigterm,
    wait_listening,
)
from simworld.change import CHANGE_HELP, ChangeError, changing_map
from simworld.maps import MapError, load_map
from wire import DecodeError, Keys, Progress, Tick, decode, encode
from wire import Fault as WireFault
from wire.messages import MAX_SCANNERS
from wire.session import (
    SessionOptions,
    closed_within,
    declare_publisher,
    loopback_options,
)
from wire.tickorder import TickOrder

MAX_ROBOTS = 100  # one machine's processes: beyond this a run fails slowly, not at once
PROGRESS_QUERY_S = 0.5  # longest wait for the recorder's answer to a progress query
STATES_AHEAD_S = 1.0  # agents' states this far from the latest tick heard: said so
BACKGROUND_NICE = 10  # the recorder (the team's router) is off the lockstep's path
# From this many robots on the agents are clients of the team's router, not peers: a
# peer mesh holds a link per pair and at 50 robots ran 3x slower, its recorder missing
# up to 1 % of the agents' states (BENCHMARKS.md, "Agents as clients of the router").
CLIENT_AGENTS_FROM = 10
STARTUP_S = 60.0
RECORDER_STALL_S = 30.0  # a recorder that has taken no tick for this long is stopped
WORLD_DT_S = 0.1  # the world's tick; btrack sim does not change it
# An agent process's start, spawn to liveliness token: 0.34-0.40 s on this 2-core
# machine (bench/agent_start.py, BENCHMARKS.md), rounded up.
BOOT_S = 0.5


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack sim",
        description="Run a simulated team on this machine, every part its own OS process: "
        "world, recorder and N agents over Zenoh on loopback; then write the report.",
    )
    p.add_argument("--robots", type=int, default=3, help="team size (default 3)")
    p.add_argument("--map", default="half-algae",
                   help="no-algae | half-algae | random-algae | FILE.png | "
                   "procedural:SEED[,length=..,edge=..,amplitude=..,algae=..] (see btrack maps) "
                   "| floe:SEED[,shape=round|elongated|bay,size=..,algae=..] or closed:FILE.png "
                   "(a closed edge: a ring, truth poses) (default half-algae)")
    p.add_argument("--scale", type=float, default=0.05, help="PNG map metres per pixel")
    p.add_argument("--start", default="ahead:1",
                   help="in-phase | ahead:K (robot K starts 72 deg ahead; default ahead:1)")
    p.add_argument("--localization", choices=["pf", "truth", "odometry"],
                   help="where agents' poses come from: pf (the localizer's particle "
                   "filters on laser scans), truth or odometry (default pf; with --hil, "
                   "truth: the hardware loop's world sends the poses)")
    p.add_argument("--scanners", type=int, metavar="N",
                   help="with pf: laser scanners in a row behind the team, each watching "
                   "its share of the edge (default one per 10 m of edge)")
    p.add_argument("--sensors", choices=["ideal", "lab"],
                   help="sensor profile: ideal (the default: the simulator's ideal laser and "
                   "sensors) or lab (the LMS's bias, noise, mixed pixels, jitter and sweep, a "
                   "Create's outline, clutter and a walking person, noisy late ice and algae "
                   "sensors with a dead band, wheel slip; the localizer set for a real LMS)")
    p.add_argument("--clouds-every", type=int, metavar="N",
                   help="with pf: every N ticks the localizer publishes a sample of each "
                   "robot's particles, which the recording keeps and Foxglove draws")
    p.add_argument("--odom-noise", type=non_negative, metavar="F",
                   help="wheel odometry noise: std of each step's distance as a fraction "
                   "of it (the world's default, 0.02)")
    p.add_argument("--odom-turn-noise", type=non_negative, metavar="F",
                   help="std of each step's turn as a fraction of it (default: --odom-noise; "
                   "a gyro-aided heading has far less)")
    p.add_argument("--duration", type=float, default=900.0, help="simulated seconds (900)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", type=Path, help="output directory (default runs/<time>)")
    p.add_argument("--realtime", action="store_true", help="pace the world on the wall clock")
    p.add_argument("--change", action="append", default=[], metavar="SPEC", help=CHANGE_HELP)
    p.add_argument("--kidnap", action="append", default=[], metavar="ROBOT@T:DX,DY",
                   help="the world carries robot ROBOT by (DX, DY) m at time T (repeatable)")
    p.add_argument("--config", metavar="FILE.toml", help="agent configuration for every agent")
    p.add_argument("--k-s", type=float, help="workload gain K_s per tick (eq. 4.3)")
    p.add_argument("--k-phi", type=float, help="phase consensus gain K_phi (eq. 4.7)")
    p.add_argument("--cycle-s", type=float,
                   help="fix the common patrol cycle period, s (default: from the team's need)")
    p.add_argument("--passes", type=int,
                   help="at least this many passes per sweep of a segment (more on long ones)")
    p.add_argument("--ns", help="run namespace (default: a fresh one per run)")
    p.add_argument("--boot-s", type=non_negative, default=BOOT_S, metavar="S",
                   help="simulated seconds a restarted or joining agent takes to start; the "
                        f"world holds its clock while the process starts ({BOOT_S:g}: "
                        "measured, bench/agent_start.py)")
    p.add_argument("--agents", choices=("auto", "peer", "client"), default="auto",
                   help="how the agents join the bus: peers linked to each other (one hop "
                   "a message, a link per pair), or clients of the team's router (one "
                   "link each, two hops); auto: clients from "
                   f"{CLIENT_AGENTS_FROM} robots on (BENCHMARKS.md) (default auto)")
    p.add_argument("--port", type=int, metavar="PORT",
                   help="the team's router listens on tcp/127.0.0.1:PORT (default: a free "
                        "port); other tools join the run there (OUT/bus.json says where)")
    p.add_argument("--fault", action="append", default=[], metavar="SPEC",
                   help="inject a fault at a simulated time (repeatable): kill:I@T, "
                   "restart:I@T (after a kill), freeze:I@T1-T2 (SIGSTOP, then SIGCONT), "
                   "join:I@T (a new robot id joins the team)")
    p.add_argument("--chaos", type=int, metavar="SEED",
                   help="also kill and restart, freeze and thaw random agents at random "
                   "times drawn from SEED")
    p.add_argument("--no-report", action="store_true", help="skip the report at the end")
    p.add_argument("--live", nargs="?", type=int, const=8765, metavar="PORT",
                   help="serve the team to Foxglove over its WebSocket protocol while it "
                   "runs (btrack view) on ws://127.0.0.1:PORT (8765)")
    p.add_argument("--no-scene", action="store_true",
                   help="skip adding the Foxglove channels to the recording at the end")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--progress-every", type=non_negative, metavar="SECONDS",
                   help="wall seconds between progress lines (1 on a terminal, else 5)")
    p.add_argument("--hil", action="store_true",
                   help="hardware in the loop: emulated Creates and LMS on pseudo-terminals "
                        "behind the real bridges (btrack bridge); --duration is wall seconds")
    p.add_argument("--engine", choices=["bus", "inprocess"], default="bus",
                   help="bus: every part its own process over Zenoh; inprocess: the whole "
                   "team in this process (deploy.engine, the same cores bit for bit), "
                   "measures and figures but no recording. A closed edge (an island map: "
                   "floe:SEED,.. or a PNG whose ice touches no border) runs either way, "
                   "with truth poses [bus]")
    p.add_argument("--hil-faults", type=float, metavar="P",
                   help="with --hil: fraction of device messages damaged on purpose (0.005)")
    return p


class Monitor:
    """The launcher's view of the run, for progress lines: it asks the recorder when it
    prints (a Zenoh query), so following the run costs no message per tick."""

    def __init__(self, session: zenoh.Session, keys: Keys):
        self.session = session
        self.keys = keys
        self.progress: Progress | None = None
        self.recorder_alive = threading.Event()
        self._alive_sub = session.liveliness().declare_subscriber(
            keys.alive_recorder(), self._on_recorder, history=True)

    def _on_recorder(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.recorder_alive.set()

    def ask(self) -> None:
        """Ask the recorder how far the run has got; keep the last answer if none comes
        (the niced recorder can be slow to answer under load)."""
        try:
            for reply in self.session.get(self.keys.progress(), timeout=PROGRESS_QUERY_S):
                if reply.ok is not None:
                    try:
                        self.progress = decode(Progress, reply.ok.payload.to_bytes())
                    except DecodeError:
                        pass
        except zenoh.ZError:
            pass

    def errors(self) -> tuple[float, float]:
        """Mean |phase error| and |workload error| over neighbour pairs, as the agents
        themselves see them (the report measures against truth), at ``states_t``: the
        agents still publishing (the recorder leaves out those that stopped)."""
        p = self.progress
        if p is None:
            return float("nan"), float("nan")
        rows = list(zip(p.phase, p.workload, strict=True))
        ep, ew = [], []
        for (pa, wa), (pb, wb) in zip(rows, rows[1:], strict=False):
            ep.append(abs(wrap_pi(pb - pa)))
            ew.append(abs(wb - wa))
        mean = lambda xs: sum(xs) / len(xs) if xs else float("nan")  # noqa: E731
        return mean(ep), mean(ew)


class Injector:
    """Carries out the fault schedule: the tick callback only notes the time and wakes
    the launcher's loop, which signals, starts and announces (Fault on the bus, for the
    recording) from its own thread. We hear the ticks through the niced recorder, up to
    seconds late under load, so the world holds after each fault's tick until it hears
    the announcement (``--hold-at``): the fault lands on that tick all the same."""

    def __init__(self, session: zenoh.Session, keys: Keys, schedule: list[faults.Fault],
                 group: ProcessGroup, agent_args: Callable[[int], list[str]]):
        self.schedule = schedule
        self.done = 0
        self.group = group
        self.agent_args = agent_args
        self.agents: dict[int, Child] = {}
        self.gone: set[int] = set()  # pids killed on purpose: not a failure
        self.starts: dict[int, int] = {}
        self.t = 0.0
        self._order: TickOrder[Tick] = TickOrder()
        self.refused = 0  # ticks refused as implausible
        self.wake = threading.Event()
        self.pub = declare_publisher(session, keys.fault())
        self._next_at = schedule[0].at_s if schedule else math.inf
        # Only a run with faults to inject needs every tick in Python.
        self._sub = (session.declare_subscriber(keys.world_tick(), self._on_tick)
                     if schedule else None)

    def _on_tick(self, sample: zenoh.Sample) -> None:
        try:
            tick = decode(Tick, sample.payload.to_bytes())
        except DecodeError:
            return
        # Only ticks in order (wire.tickorder) move the clock the faults are timed by: a
        # forged tick from the far future would fire every fault at once, and a lost one
        # must not stop the clock for the rest of the run.
        if abs(tick.t - tick.k * WORLD_DT_S) > 1e-6 * max(1.0, tick.t):
            self.refused += 1
            return
        out = self._order.offer(tick.k, tick)
        self.refused += len(out.refused)
        if not out.taken:
            return
        self.t = max(self.t, out.taken[-1].t)
        if self.t >= self._next_at:
            self.wake.set()

    def start_agent(self, agent: int) -> Child:
        n = self.starts.get(agent, 0)
        self.starts[agent] = n + 1
        name = f"agent{agent}" if n == 0 else f"agent{agent}.{n}"
        child = self.group.start(name, self.agent_args(agent))
        self.agents[agent] = child
        return child

    def fire_due(self) -> list[str]:
        """Carry out every fault that is due; return a line for each."""
        self.wake.clear()
        lines = []
        for f in faults.due(self.schedule, self.done, self.t):
            self.done += 1
            child = self.agents.get(f.agent)
            if f.kind in ("restart", "join"):
                child = self.start_agent(f.agent)
            elif child is not None and child.alive():
                sig = {"kill": signal.SIGKILL, "freeze": signal.SIGSTOP,
                       "thaw": signal.SIGCONT}[f.kind]
                os.kill(child.pid, sig)
                if f.kind == "kill":
                    self.gone.add(child.pid)
            pid = child.pid if child is not None else 0
            self.pub.put(encode(WireFault(self.t, f.kind, f.agent, pid, time.time_ns())))
            lines.append(f"t = {self.t:7.1f} s: {f.kind} agent {f.agent} (pid {pid}), "
                         f"scheduled at {f.at_s:g} s")
        self._next_at = (self.schedule[self.done].at_s if self.done < len(self.schedule)
                         else math.inf)
        return lines

    def unexpected_exit(self) -> Child | None:
        for child in self.agents.values():
            if child.pid not in self.gone and not child.alive():
                return child
        return None


def _schedule(args: argparse.Namespace) -> tuple[list[faults.Fault], int]:
    """The run's fault schedule and the number of robot bodies the world needs."""
    schedule = [f for spec in args.fault for f in faults.parse_fault(spec)]
    if args.chaos is not None:
        schedule += faults.chaos_schedule(args.chaos, args.robots, args.duration)
    schedule.sort()
    return schedule, faults.check_schedule(schedule, args.robots)


def fail(group: ProcessGroup, child: Child, what: str, name: str = "btrack sim") -> int:
    """Say which process failed and how, with the end of its log; end the run's
    processes; exit code 1 (``btrack sim`` and its hardware loop alike)."""
    print(f"\n{name}: {child.name} {what} (exit code {child.proc.returncode}); "
          f"its log {child.log_path}:\n{child.log_tail()}", file=sys.stderr)
    group.stop_all()
    return 1


# What the hardware loop (--hil) does not do yet: refused by name there, never ignored.
HIL_REFUSED = (("fault", "--fault"), ("chaos", "--chaos"), ("kidnap", "--kidnap"),
               ("odom_noise", "--odom-noise"), ("odom_turn_noise", "--odom-turn-noise"),
               ("scanners", "--scanners"), ("sensors", "--sensors"),
               ("live", "--live"), ("clouds_every", "--clouds-every"),
               ("engine", "--engine"), ("change", "--change"), ("agents", "--agents"))


def hil_refusal(args: argparse.Namespace) -> str | None:
    """Why an option cannot go with --hil (or --hil-faults without it); None if none.
    The hardware loop runs on the wall clock with its own devices' odometry, on the
    particle filter's poses from the emulated LMS (or the poses its world sends, with
    --localization truth): faults, kidnaps, odometry noise and dead reckoning are the
    simulator's."""
    if not args.hil:
        return "--hil-faults needs --hil" if args.hil_faults is not None else None
    defaults = build_parser().parse_args([])
    given = [flag for name, flag in HIL_REFUSED if getattr(args, name) != getattr(defaults, name)]
    if args.localization not in (None, "truth", "pf"):
        given.append(f"--localization {args.localization}")
    if args.boot_s != defaults.boot_s:
        given.append("--boot-s")
    if given:
        return (f"{', '.join(given)}: not with --hil (the hardware loop runs its own "
                "devices on the wall clock, on the filter's or its world's poses)")
    return None


def ring_refusal(args: argparse.Namespace) -> str | None:
    """What a ring round a closed edge cannot do over the bus yet; None if nothing."""
    if args.localization not in (None, "truth"):
        return (f"--localization {args.localization}: a ring on a closed edge runs with truth "
                "poses only, so far (the laser's view round a floe is later work)")
    given = [flag for flag, value in (("--sensors lab", args.sensors == "lab"),
                                      ("--hil", args.hil)) if value]
    if given:
        return (f"{', '.join(given)}: not on a ring round a closed edge yet (the lab's "
                "sensors and the hardware loop round a floe are later work)")
    return None


def refusal(args: argparse.Namespace, bodies: int) -> str | None:
    """Why the run cannot go as asked, before any process starts; None if it can.
    ``bodies`` is the team plus every id that joins (``run`` has checked the team)."""
    if bodies > MAX_ROBOTS:
        return f"the team and the ids that join are {bodies} robots; at most {MAX_ROBOTS}"
    if args.port is not None and not 1 <= args.port <= 65535:
        return f"--port must be between 1 and 65535, not {args.port}"
    if args.live is not None and not 1 <= args.live <= 65535:
        return f"--live must be a port between 1 and 65535, not {args.live}"
    if not (math.isfinite(args.duration) and args.duration > 0):
        return f"--duration must be a positive number of seconds, not {args.duration:g}"
    if args.scanners is not None and not 1 <= args.scanners <= MAX_SCANNERS:
        return f"--scanners must be between 1 and {MAX_SCANNERS}, not {args.scanners}"
    if args.scanners is not None and args.localization not in (None, "pf"):
        return f"--scanners: the laser scans only with --localization pf, not {args.localization}"
    if args.clouds_every is not None and not args.clouds_every >= 1:
        return f"--clouds-every must be at least 1, not {args.clouds_every}"
    if args.clouds_every is not None and args.localization not in (None, "pf"):
        return (f"--clouds-every: particles come from the localizer, with --localization pf, "
                f"not {args.localization}")
    if args.ns is not None:
        try:
            Keys(args.ns)
        except ValueError as exc:
            return f"--ns: {exc}"
    overrides = {"gains": {"k_s": args.k_s, "k_phi": args.k_phi, "cycle_s": args.cycle_s},
                 "patrol": {"passes_per_sweep": args.passes}}
    try:
        gains, _, _ = agent_config.load(args.config, overrides)
    except agent_config.ConfigError as exc:
        return f"--config: {exc}"
    try:
        gmap = load_map(args.map, args.scale, args.seed)
    except MapError as exc:
        return f"--map: {exc}"
    try:
        change = changing_map(gmap, args.change, args.scale, args.seed)
    except ChangeError as exc:
        return str(exc)
    if change is not None and args.sensors == "lab":
        return "--change: the lab sensors read a static map only, so far; use --sensors ideal"
    if change is not None and any(c.t0 >= args.duration for c in change.changes):
        late = next(c for c in change.changes if c.t0 >= args.duration)
        return (f"--change {late} would begin after the run's end (--duration "
                f"{args.duration:g} s)")
    if gmap.closed and args.engine != "inprocess":
        why = ring_refusal(args)
        if why:
            return why
    edge = gmap.edge_hi - gmap.edge_lo
    if bodies * gains.min_segment_m > edge:
        return (f"{bodies} robots need {bodies * gains.min_segment_m:.2f} m of edge at "
                f"min_segment_m = {gains.min_segment_m:g} m each; the edge of {args.map} is "
                f"{edge:.2f} m long (at most {int(edge / gains.min_segment_m)} robots)")
    return None


def _sensor_args(args: argparse.Namespace) -> list[str]:
    """What the agents are told of their ice and algae sensors: under ``--sensors lab``
    the profile's latency and dead band (a robot's agent has them from the sensors'
    data sheet, in its configuration); the ideal sensors have neither."""
    if args.sensors != "lab":
        return []
    from simworld.sensors import profile

    lab = profile("lab")
    assert lab is not None
    return ["--sensor-latency", repr(lab.sensor_latency_s), "--sensor-band",
            repr(lab.dead_band_m)]


def _scanners(args: argparse.Namespace) -> int:
    """The world's row of scanners: ``--scanners``, else one per 10 m of the map's edge
    (``simworld.laser.scanner_count``, as the world counts them); the localizer drops a
    scan of any other row."""
    if args.scanners is not None:
        return int(args.scanners)
    from simworld.laser import scanner_count

    gmap = load_map(args.map, args.scale, args.seed)
    return scanner_count(gmap.edge_lo, gmap.edge_hi)


def _make_out(out: Path) -> str | None:
    """Create the output directory; why not, if it cannot be."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        return f"--out {out}: cannot write there: {exc.strerror or exc}"
    return None


def run(args: argparse.Namespace) -> int:
    stop_on_sigterm()
    if not 1 <= args.robots <= MAX_ROBOTS:
        print(f"btrack sim: --robots must be between 1 and {MAX_ROBOTS}, not {args.robots}",
              file=sys.stderr)
        return 2
    try:
        schedule, bodies = _schedule(args)
    except faults.FaultSpecError as exc:
        print(f"btrack sim: {exc}", file=sys.stderr)
        return 2
    why = hil_refusal(args) or refusal(args, bodies)
    asked_localization = args.localization  # the in-process engine has its own default
    closed = why is None and load_map(args.map, args.scale, args.seed).closed
    if args.localization is None:  # a ring has no laser's view round it yet: truth
        args.localization = "truth" if closed else "pf"
    if why is None and not args.hil:
        late = [f for f in schedule if f.at_s >= args.duration]
        if late:
            why = (f"--fault {late[0].kind}:{late[0].agent}@{late[0].at_s:g} would come after "
                   f"the run's end (--duration {args.duration:g} s)")
    if why is None and args.port is not None and args.engine == "bus" and not bindable(
            args.port):
        why = (f"--port {args.port}: something already listens on loopback port "
               f"{args.port}; choose another, or leave --port out and one is drawn")
    out: Path = args.out or Path("runs") / time.strftime(
        "hil-%Y%m%d-%H%M%S" if args.hil else "%Y%m%d-%H%M%S")
    why = why or _make_out(out)
    if why is not None:
        print(f"btrack sim: {why}", file=sys.stderr)
        return 2
    defaults = Gains()  # a ring's bound is checked where its controllers are made
    problems = check_gains(args.robots, defaults.k_phi if args.k_phi is None else args.k_phi,
                           defaults.k_s if args.k_s is None else args.k_s, 2.0,
                           closed=closed and args.engine == "bus")
    if problems:
        print("btrack sim: unstable gains: " + "; ".join(problems), file=sys.stderr)
        return 2
    args.out = out
    if args.engine == "inprocess":
        from deploy import inprocess

        return inprocess.run(args, out, asked_localization)
    if args.hil:  # the hardware stack with emulated devices: hwbridge/hil.py
        from hwbridge import hil

        return hil.run(args)
    ns = args.ns or f"btrack/sim-{os.getpid()}-{int(time.time() * 1000) % 10**9}"
    keys = Keys(ns)
    port = args.port if args.port is not None else free_port()
    # The recorder is the team's router (niced: it carries only what it records and
    # what the launcher, its client, hears). The processes of the lockstep (world,
    # agents, localizer) are peers that connect to it and link to each other directly,
    # one hop per message; every message reaches the recorder in one hop too, with no
    # router process forwarding to it (BENCHMARKS.md).
    hub = f"tcp/127.0.0.1:{port}"
    agents_mode = args.agents if args.agents != "auto" else (
        "client" if args.robots >= CLIENT_AGENTS_FROM else "peer")
    (out / "bus.json").write_text(json.dumps({"ns": ns, "connect": hub,
                                              "agents": agents_mode}) + "\n")
    client = SessionOptions(ns=ns, mode="client", connect=(hub,), multicast=False)
    member = loopback_options(ns, port).to_args()
    # the agents' own: as the other members, or clients of the router (a link each)
    agent_member = member if agents_mode == "peer" else client.to_args()
    group = ProcessGroup(out / "logs")
    print(f"btrack sim: {args.robots} robots, map {args.map}, start {args.start}, "
          f"localization {args.localization}, {args.duration:g} s simulated -> {out}")
    t_wall0 = time.monotonic()
    try:
        recorder = group.start("recorder", [
            "record", "--out", str(out), "--ns", ns, "--mode", "router", "--listen", hub,
            "--no-multicast"], nice=BACKGROUND_NICE)
        if not wait_listening(port, recorder, STARTUP_S):
            return fail(group, recorder, f"did not listen on {hub} within {STARTUP_S:g} s")
        with closed_within(client) as session, group.stopped_on_interrupt():
            monitor = Monitor(session, keys)
            while not monitor.recorder_alive.wait(0.2):
                if not recorder.alive():
                    return fail(group, recorder, "failed to start")
                if time.monotonic() - t_wall0 > STARTUP_S:
                    return fail(group, recorder, f"did not come up within {STARTUP_S:g} s")
            if args.live is not None:  # off the lockstep: a niced client of the router
                group.start("view", ["view", "--port", str(args.live), "--ns", ns, "--mode",
                                     "client", "--connect", hub, "--no-multicast"],
                            nice=BACKGROUND_NICE)
                print(f"btrack sim: live view on ws://127.0.0.1:{args.live} (Foxglove: Open "
                      "connection, Foxglove WebSocket; layout docs/foxglove-layout.json)")

            def agent_args(i: int) -> list[str]:
                team = args.robots if i < args.robots else bodies
                return ["agent", "--id", str(i), "--robots", str(team),
                        *forward_flags(args, AGENT_FLAGS), *_sensor_args(args),
                        *agent_member]

            injector = Injector(session, keys, schedule, group, agent_args)
            for i in range(args.robots):
                injector.start_agent(i)
            vital: list[Child] = []  # processes the run cannot go on without
            if args.localization == "pf":
                vital.append(group.start("localizer", [
                    "localizer", "--robots", str(bodies), "--seed", str(args.seed),
                    "--scanners", str(_scanners(args)),
                    *(["--sensors", args.sensors] if args.sensors else []),
                    *(["--clouds-every", str(args.clouds_every)] if args.clouds_every else []),
                    *member]))
            if schedule and not args.quiet:
                print("btrack sim: faults: " + ", ".join(
                    f"{f.kind}:{f.agent}@{f.at_s:g}" for f in schedule))
            world_args = ["world", "--robots", str(bodies), "--team", str(args.robots),
                          "--boot-s", str(args.boot_s),
                          "--map", args.map,
                          "--scale", str(args.scale), "--start", args.start,
                          "--localization", args.localization, "--duration", str(args.duration),
                          "--seed", str(args.seed), "--wait-recorder", *member]
            if args.realtime:
                world_args.append("--realtime")
            else:  # each fault lands on its tick, however late we hear the clock
                for f in schedule:
                    world_args += ["--hold-at", str(f.at_s)]
            for spec in args.kidnap:
                world_args += ["--kidnap", spec]
            for spec in args.change:
                world_args += ["--change", spec]
            world_args += forward_flags(args, ODOM_FLAGS)
            if args.scanners is not None:
                world_args += ["--scanners", str(args.scanners)]
            if args.sensors:
                world_args += ["--sensors", args.sensors]
            world = group.start("world", world_args)
            code = _watch(args, group, monitor, world, injector, recorder, vital)
            if code:
                return code
            _wait_for_recorder(recorder, monitor)
            group.stop_all()
            missing = _recording_missing(recorder, round(args.duration / WORLD_DT_S))
            if missing:
                print(f"\nbtrack sim: the recording is incomplete: {missing}; its log "
                      f"{recorder.log_path}", file=sys.stderr)
                return 1
            if injector.refused:
                print(f"btrack sim: {injector.refused} world ticks were refused as "
                      "implausible (not the next tick)", file=sys.stderr)
            faulty = own_faults(group.children)
            if faulty:
                print(f"btrack sim: {faulty}", file=sys.stderr)
    except KeyboardInterrupt as exc:
        return stop_interrupted(group, exc, "btrack sim")
    finally:
        group.stop_all()
    wall = time.monotonic() - t_wall0
    print(f"\nbtrack sim: run finished in {wall:.1f} s wall; recording {out / 'run.mcap'}")
    report_and_scene(out, args.no_report, args.no_scene, "btrack sim")
    return 0


def report_and_scene(out: Path, no_report: bool, no_scene: bool, name: str,
                     extra: dict[str, Any] | None = None) -> None:
    """After a run: the report (``extra`` added to its summary.json) while the Foxglove
    conversion runs beside it as its own process, then the conversion's end. Without
    the report, ``extra`` alone is printed."""
    scene = start_scene(out, no_scene)
    try:
        if no_report:
            if extra is not None:
                print(json.dumps(extra, indent=2))
        else:
            from report.cli import make_report

            summary = make_report(out)
            if extra is not None:
                from report.summary import write_summary

                summary.update(extra)
                write_summary(out / "summary.json", summary)
            print(json.dumps(summary, indent=2))
            print(f"{name}: report in {out / 'report.md'}")
    except BaseException:
        end_scene(scene)
        raise
    finish_scene(scene, out, name)


def start_scene(out: Path, skip: bool) -> subprocess.Popen[str] | None:
    """The Foxglove channels are made from the finished recording (scene.convert), not
    by the recorder on the lockstep's cores: ``btrack scene OUT`` in a process of its
    own, beside the report, which reads the raw channels either way."""
    if skip:
        return None
    return subprocess.Popen(
        [sys.executable, "-m", "btrack", "scene", str(out)], stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def end_scene(scene: subprocess.Popen[str] | None) -> None:
    """End ``start_scene``'s process (ours, by its pid) on an interruption: the raw
    recording stays as it was (the conversion replaces it only once it is whole)."""
    if scene is not None and scene.poll() is None:
        scene.kill()
        scene.wait()
    if scene is not None:
        for stream in (scene.stdout, scene.stderr):
            if stream is not None:
                stream.close()


def finish_scene(scene: subprocess.Popen[str] | None, out: Path, who: str) -> None:
    """Wait for ``start_scene``'s process and say how it went."""
    if scene is None:
        return
    try:
        stdout, stderr = scene.communicate()
    except BaseException:
        end_scene(scene)
        raise
    if scene.returncode == 0:
        print(f"{who}: Foxglove channels added to {out / 'run.mcap'} {stdout.strip()} "
              "(layout: docs/foxglove-layout.json)")
    else:
        print(f"{who}: no Foxglove channels: {stderr.strip()[-500:]}", file=sys.stderr)


def _watch(args: argparse.Namespace, group: ProcessGroup, monitor: Monitor, world: Child,
           injector: Injector, recorder: Child, vital: list[Child]) -> int:
    """Show progress and inject faults until the world ends; fail fast if a process
    dies that was not killed on purpose."""
    last_print = time.monotonic()
    last_t, last_wall = 0.0, time.monotonic()
    tty = sys.stdout.isatty()
    every = args.progress_every if args.progress_every is not None else 1.0 if tty else 5.0
    while world.alive():
        if injector.wake.wait(0.2):
            for line in injector.fire_due():  # shown even when quiet: it changes the run
                print(("\n" if tty else "") + "btrack sim: " + line, flush=True)
        if world.proc.poll() is not None:
            break
        if (not recorder.alive() and recorder.proc.returncode == 0
                and recorder.last_json().get("done")):
            continue  # the recorder ends by itself once it has the final tick
        dead = injector.unexpected_exit() or (None if recorder.alive() else recorder) or next(
            (c for c in vital if not c.alive()), None)
        if dead is not None:
            return fail(group, dead, "exited early")
        now = time.monotonic()
        if args.quiet or now - last_print < every:
            continue
        monitor.ask()
        if monitor.progress is not None:
            shown = _progress_line(monitor, args.duration, last_t, now - last_wall, every)
            if shown is None:
                continue  # the recorder's time has not moved yet: no news, ask again soon
            print("\r" + shown if tty else shown, end="" if tty else "\n", flush=True)
            last_print, last_t, last_wall = now, monitor.progress.t, now
    if world.proc.returncode != 0:
        return fail(group, world, "failed")
    return 0


def _progress_line(monitor: Monitor, duration: float, last_t: float, wall_s: float,
                   every: float) -> str | None:
    """One progress line, or None while the recorder's simulated time stands where the
    last line left it (it lags the world under load); a stand of five intervals is
    shown as a stall, not as a speed of zero."""
    p = monitor.progress
    assert p is not None
    t = p.t
    if t <= last_t and wall_s < 5 * every:
        return None
    rate = (t - last_t) / wall_s
    speed = f"{rate:6.{1 if rate >= 1 else 2}f}x real time" if t > last_t else (
        f"stalled for {wall_s:.0f} s")
    fmt = lambda x: "n/a" if math.isnan(x) else f"{x:.3f}"  # noqa: E731
    ep, ew = monitor.errors()
    # under load the recorder hears the agents' states well before the world's ticks:
    # the errors are then of a later time, which the line says
    ahead = (f" (agents at {p.states_t:.1f} s)"
             if p.states_t >= 0 and abs(p.states_t - t) > STATES_AHEAD_S else "")
    return (f"t = {t:7.1f} / {duration:g} s  {speed}  |e_phi| {fmt(ep)} rad  "
            f"|e_psi| {fmt(ew)} m^2{ahead}  live {p.live}")


def _wait_for_recorder(recorder: Child, monitor: Monitor) -> None:
    """Wait for the recorder to write the run's last tick and end by itself, as long as
    it is getting on: a recorder lagging under load is waited for, not cut off; one that
    has stopped getting on for ``RECORDER_STALL_S`` is stopped (it finishes its file)."""
    last_k, last_move = -1, time.monotonic()
    while recorder.alive():
        try:
            recorder.proc.wait(1.0)
            return
        except Exception:
            pass
        monitor.ask()
        k = monitor.progress.k if monitor.progress is not None else -1
        if k > last_k:
            last_k, last_move = k, time.monotonic()
        elif time.monotonic() - last_move > RECORDER_STALL_S:
            print(f"\nbtrack sim: the recorder made no progress for {RECORDER_STALL_S:g} s "
                  f"(at tick {last_k}); stopping it", file=sys.stderr)
            return


def _recording_missing(recorder: Child, total: int) -> str:
    """What the recording lacks of a run of ``total`` ticks, from the recorder's own
    count; "" if nothing."""
    counts = recorder.last_json()
    if not counts:
        return f"the recorder gave no count (exit code {recorder.proc.returncode})"
    ticks = int(counts.get("ticks", 0))
    if ticks < total or not counts.get("done"):
        return (f"it holds {ticks} of the run's {total} ticks"
                + ("" if counts.get("done") else ", not the final one"))
    return ""


def main(argv: list[str] | None = None) -> int:
    return run(build_parser().parse_args(argv))

"""``btrack world``: the simulator process, the run's clock (DESIGN.md "Time").

Lockstep (default): tick k publishes the laser Scan (with ``--localization pf``),
every robot's Sense (with the robot's truth or odometry pose in it, unless a localizer
gives the poses) and then the team's Truth (one message, for the recorder), waits for
tick k's Cmd from every live agent (a dead agent is not waited for, a silent one at
most ``--cmd-timeout``), publishes the Tick and steps the world. ``--realtime`` paces
ticks on the wall clock instead and uses each robot's latest command.
With ``--localization pf`` the Senses carry no pose: the localizer turns tick k's
Scan and Sense into tick k's poses, the agents act on them, and the world, which
waited for the localizer's liveliness before tick 0, waits for their commands as
usual. Scans come at the control rate (one per tick).
Membership is Zenoh liveliness on ``keys.alive('*')``. Zenoh callbacks only push into
a queue; everything else happens on the main thread.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import queue
import signal
import sys
import time

import zenoh

from simworld.change import CHANGE_HELP, ChangeError, ChangingMap, changing_map
from simworld.laser import Laser, laser_row
from simworld.maps import ROBOT_ROOM_M
from simworld.sensors import PROFILES, LabLaser, LabSensing, Slip, Walker, clutter_legs, profile
from simworld.shell import ALIVE, Event, WorldShell, load_checked_map
from simworld.world import ODOM_NOISE, ROBOT_RADIUS_M, World, parse_start
from wire import (
    Cmd,
    DecodeError,
    Fault,
    Keys,
    Scan,
    Sense,
    Tick,
    Truth,
    decode,
    encode,
)
from wire.messages import MAX_SCANNERS
from wire.session import (
    add_session_args,
    bounded_session,
    declare_publisher,
    options_from_args,
)

log = logging.getLogger("btrack.world")

INFO_EVERY_TICKS = 100

# the world's own queue items, beside the shell's membership events
_CMD, _FAULT = "cmd", "fault"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack world", description="The simulator: maps, kinematics, sensors, the clock."
    )
    p.add_argument("--robots", type=int, default=3, help="number of robots (default 3)")
    p.add_argument("--team", type=int,
                   help="how many of them (ids 0..TEAM-1) start on the start line; the rest "
                   "wait behind it until their agent joins (default: all)")
    p.add_argument(
        "--map",
        default="half-algae",
        help="no-algae | half-algae | random-algae | FILE.png | "
        "procedural:SEED[,length=..,edge=..,amplitude=..,algae=..] (see btrack maps) "
        "(default half-algae)",
    )
    p.add_argument("--scale", type=float, default=0.05, help="PNG metres per pixel (0.05)")
    p.add_argument("--start", default="in-phase", help="in-phase | ahead:K (default in-phase)")
    p.add_argument(
        "--localization",
        choices=["truth", "odometry", "pf"],
        default="truth",
        help="the pose each robot's Sense carries (default truth); pf: none, the world "
        "publishes laser scans and waits for the localizer's poses",
    )
    p.add_argument(
        "--laser-noise",
        type=float,
        default=0.01,
        help="laser range noise, std in m (0.01)",
    )
    p.add_argument(
        "--sensors",
        choices=PROFILES,
        default="ideal",
        help="sensor profile (default ideal: the world as it always was); lab: the LMS's "
        "bias, noise, mixed pixels, jitter and sweep, a Create's outline, clutter and a "
        "walking person, noisy and late ice and algae sensors with a dead band, wheel slip "
        "(simworld/sensors.py)",
    )
    p.add_argument(
        "--scanners",
        type=int,
        default=0,
        metavar="N",
        help="laser scanners in a row behind the team, each in the middle of its share of "
        "the edge (default 0: one per 10 m of edge)",
    )
    p.add_argument(
        "--walls",
        action="store_true",
        help="walls around the scene for the laser (a box 1 m beyond the edge's ends)",
    )
    p.add_argument(
        "--kidnap",
        action="append",
        default=[],
        metavar="ROBOT@T:DX,DY",
        help="carry robot ROBOT by (DX, DY) m at simulated time T s, odometry unaware "
        "(repeatable)",
    )
    p.add_argument("--duration", type=float, default=600.0, help="simulated seconds (600)")
    p.add_argument("--seed", type=int, default=1, help="seed of the map and the noise (1)")
    p.add_argument("--dt", type=float, default=0.1, help="control period, s (0.1)")
    p.add_argument("--boot-s", type=float, default=0.0, metavar="S",
                   help="simulated seconds a restarted or joining agent takes to start, as on "
                        "a robot's computer: the world holds its clock until the new process "
                        "is alive, then its robot gets no sensing for S (0)")
    p.add_argument(
        "--odom-noise",
        type=float,
        default=ODOM_NOISE,
        help=f"odometry noise: std of each step's distance, as a fraction of it ({ODOM_NOISE})",
    )
    p.add_argument(
        "--odom-turn-noise",
        type=float,
        help="std of each step's turn, as a fraction of it (default: --odom-noise); "
        "a robot with a gyro for its heading has far less than its wheels give",
    )
    p.add_argument("--realtime", action="store_true", help="pace ticks on the wall clock")
    p.add_argument(
        "--cmd-timeout",
        type=float,
        default=2.0,
        help="wall seconds to wait for a live agent's command (2.0)",
    )
    p.add_argument(
        "--startup-timeout",
        type=float,
        default=60.0,
        help="wall seconds to wait for all agents before tick 0 (60)",
    )
    p.add_argument(
        "--settle",
        type=float,
        default=0.5,
        help="wall seconds between seeing the whole team and tick 0, so that each "
        "agent's subscription to its neighbours' states reaches them before they "
        "publish their first (0.5)",
    )
    p.add_argument(
        "--hold-at",
        type=float,
        action="append",
        default=[],
        metavar="T",
        help="lockstep: after the first tick at or past simulated time T, wait for the "
        "launcher's fault announcement (a Fault at T or later) before going on, so an "
        "injected fault lands on that exact tick however late the launcher hears the "
        "clock (repeatable)",
    )
    p.add_argument(
        "--hold-timeout",
        type=float,
        default=10.0,
        help="wall seconds to wait at a --hold-at before going on without it (10)",
    )
    p.add_argument("--change", action="append", default=[], metavar="SPEC",
                   help=CHANGE_HELP)
    p.add_argument(
        "--wait-recorder",
        action="store_true",
        help="also wait for the recorder's liveliness token before tick 0",
    )
    add_session_args(p)
    return p


def lasers(world: World, args: argparse.Namespace) -> list[Laser]:
    """The row of scanners behind the team (``laser_row``): ``--scanners`` of them or
    one per 10 m of edge; ``--walls`` boxes the scene."""
    m = world.map
    return laser_row(m.edge_lo, m.edge_hi, m.y_top, args.scanners or None, args.laser_noise,
                     args.seed, ROBOT_RADIUS_M, args.walls)


class WorldProcess(WorldShell):
    """The simulator's shell around a ``World`` (``WorldShell`` and its commands, faults
    and sensing) and its clock: the lockstep or the wall clock."""

    def __init__(self, args: argparse.Namespace, world: World, session: zenoh.Session) -> None:
        super().__init__(args, world, session, localization=args.localization,
                         realtime=bool(args.realtime), localizer=args.localization == "pf",
                         team=args.team)
        # Live agents that have sent no command since their token came up, and timed out
        # once: not waited for again until they send one (a stray token of an id in
        # range, or a process that is up but does not act, must not stall every tick).
        self.mute: set[int] = set()
        self.silent: set[int] = set()
        self.lasers = lasers(world, args) if args.localization == "pf" else []
        self.profile = profile(args.sensors)
        self.lab_lasers: list[LabLaser] = []
        self.lab_sensing: LabSensing | None = None
        if self.profile is not None:
            p, m = self.profile, world.map
            clutter = clutter_legs(m.edge_lo, m.edge_hi, -ROBOT_ROOM_M) if p.clutter else []
            walker = (Walker(m.edge_lo, m.edge_hi, -ROBOT_ROOM_M + 0.4, 0.9, p.person_speed,
                             p.leg_radius_m, p.stride_m, p.step_s) if p.person else None)
            self.lab_lasers = [LabLaser(las, p, clutter, walker) for las in self.lasers]
            self.lab_sensing = LabSensing(p, world.n, args.seed)
        self.kidnaps = parse_kidnaps(args.kidnap, self.dt)
        self.dropped = 0
        self.timeouts = 0
        self.holds = sorted(args.hold_at)  # simulated times to hold at, next first
        self.fault_t = -math.inf  # the latest fault the launcher announced
        # Restarted or joining agents: the simulated time until which each one is still
        # starting (its robot gets no sensing, nobody waits for its command), and those
        # whose process the clock holds for until its token is up.
        self.booting: dict[int, float] = {}
        self.awaited: set[int] = set()
        self.edge_lo, self.edge_hi = world.map.edge_lo, world.map.edge_hi
        self.pose_source = args.localization
        k = self.keys

        def pub(key: str) -> zenoh.Publisher:
            return declare_publisher(session, key)

        self.pub_truth = pub(k.truth())
        self.pub_sense = [pub(k.sense(i)) for i in range(self.n)]
        self.pub_scan = pub(k.scan())
        put = self.events.put
        self._subs = [
            session.declare_subscriber(
                k.cmd("*"), lambda s: put((_CMD, str(s.key_expr), s.payload.to_bytes()))
            ),
            session.declare_subscriber(
                k.fault(), lambda s: put((_FAULT, str(s.key_expr), s.payload.to_bytes()))
            ),
        ]

    # events ------------------------------------------------------------------
    def joined(self, robot: int, up: bool) -> None:
        if up:
            self.mute.add(robot)  # until its first command
            self.awaited.discard(robot)
        else:
            self.mute.discard(robot)
            self.silent.discard(robot)

    def _handle(self, item: Event) -> Cmd | None:
        """Apply a membership event, a command or a fault; return a valid Cmd, or None."""
        kind, key, value = item
        if kind == _CMD:
            try:
                cmd = decode(Cmd, value)
            except DecodeError as exc:
                self._drop(key, str(exc))
                return None
            if cmd.robot != Keys.robot_of(key) or not 0 <= cmd.robot < self.n:
                self._drop(key, f"robot {cmd.robot} on this key")
                return None
            self.mute.discard(cmd.robot)
            self.silent.discard(cmd.robot)
            return cmd
        if self.membership(item):
            return None
        if kind == _FAULT:
            try:
                fault = decode(Fault, value)
            except DecodeError as exc:
                log.warning("dropped a fault announcement: %s", exc)
                return None
            self.fault_t = max(self.fault_t, fault.t)
            if fault.kind in ("restart", "join") and 0 <= fault.agent < self.n:
                self.booting[fault.agent] = fault.t + self.args.boot_s
                if fault.agent not in self.live:
                    self.awaited.add(fault.agent)
        return None

    def _drop(self, key: str, why: str) -> None:
        self.dropped += 1
        if self.dropped <= 10:
            log.warning("dropped a command on %s: %s", key, why)

    # publishing --------------------------------------------------------------
    def publish_sensing(self, k: int, t: float) -> None:
        world, dt, lo, hi = self.world, self.dt, self.edge_lo, self.edge_hi
        for robot, dx, dy in self.kidnaps.pop(k, []):
            world.move(robot, dx, dy)
            log.warning("tick %d: robot %d carried by (%g, %g) m", k, robot, dx, dy)
        odometry = self.pose_source == "odometry"
        closed = world.map.closed
        truth = [world.truth(i) for i in range(self.n)]
        motions = list(world.motion)
        for j, laser in enumerate(self.lasers):  # the localizer publishes the poses
            s = laser.scanner
            if self.lab_lasers:
                ranges = self.lab_lasers[j].scan(truth, motions, dt, t)
            else:
                ranges = laser.scan([(x, y) for x, y, _ in truth])
            self.pub_scan.put(encode(Scan(t, k, ranges, s.x, s.y, s.theta, s.angle_min,
                                          s.angle_step, s.range_max, j, len(self.lasers))))
        booted = [i for i, until in self.booting.items() if t >= until - 1e-9]
        for i in booted:
            del self.booting[i]
        if booted and closed:
            # a ring's agent takes its edge frame from the contour: one that has just
            # started gets it with its first sensing, not up to INFO_EVERY_TICKS later
            self.publish_info()
        for i in range(self.n):
            if i in self.booting:
                continue  # still starting: no sensing yet
            r = world.sense(i)
            if self.lab_sensing is not None:  # what the robot's sensors say, late and noisy
                x, y, _ = world.truth_back(i, self.lab_sensing.profile.sensor_latency_s, dt)
                ice, algae = self.lab_sensing.read(i, world.map, x, y)
                r = dataclasses.replace(r, ice=ice, algae=algae)
            if not self.lasers:  # the pose travels in the Sense
                pose = list(world.odometry_pose(i) if odometry else truth[i])
                source = self.pose_source
            else:
                pose, source = [], ""
            sense = Sense(t, k, i, r.ice, r.algae, r.odom_dist_m, r.odom_dtheta, lo, hi, dt,
                          pose, source, closed)
            self.pub_sense[i].put(encode(sense))  # an agent may act on its Sense
        # for the recorder only, after the agents' inputs; one message for the team
        self.pub_truth.put(encode(Truth.of_team(t, k, truth)))

    def frame_due(self, k: int) -> bool:
        """Whether tick k begins a new frame of a changing map's true depth."""
        change: ChangingMap | None = self.world.change
        return change is not None and change.frame_due(k, self.dt)

    # the clock ---------------------------------------------------------------
    def wait_for_team(self) -> bool:
        """Block until all n agents (and the recorder if asked) are alive."""
        deadline = time.monotonic() + self.args.startup_timeout
        while not self.stopping:
            if self.ready():
                return True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            try:
                self._handle(self.events.get(timeout=remaining))
            except queue.Empty:
                break
        if not self.stopping:
            print(f"btrack world: {self.waiting_for()} not alive after "
                  f"{self.args.startup_timeout:g} s", file=sys.stderr)
        return False

    def run_lockstep(self, total: int) -> int:
        events, timeout, world, dt = self.events, self.args.cmd_timeout, self.world, self.dt
        k = 0
        while k < total and not self.stopping:
            t = k * dt
            if k and (k % INFO_EVERY_TICKS == 0 or self.frame_due(k)):
                self.publish_info()
            self.publish_sensing(k, t)
            pending = self.live - self.silent - set(self.booting)
            cmds: dict[int, tuple[float, float]] = {}
            began = time.monotonic()
            deadline = began + timeout
            while pending and not self.stopping:
                remaining = deadline - time.monotonic()
                try:
                    item = events.get(timeout=remaining) if remaining > 0 else events.get_nowait()
                except queue.Empty:
                    self.timeouts += len(pending)
                    log.warning(
                        "tick %d: no command from %s in %.1f s", k, sorted(pending), timeout
                    )
                    never = pending & self.mute
                    if never:
                        self.silent |= never
                        log.warning("agents %s are alive but have never sent a command: "
                                    "not waited for until they do", sorted(never))
                    break
                cmd = self._handle(item)
                if cmd is not None and cmd.k == k:
                    cmds[cmd.robot] = (cmd.v, cmd.omega)
                    pending.discard(cmd.robot)
                elif item[0] == ALIVE:
                    pending &= self.live  # an agent that left is not waited for
            if self.stopping:
                break
            waited_ms = (time.monotonic() - began) * 1000.0
            live = sorted(self.live)
            self.pub_tick.put(encode(Tick(t, k, live, waited_ms, k == total - 1,
                                          time.time_ns(), self.dropped, self.rejected)))
            world.step({i: c for i, c in cmds.items() if i in self.live}, dt)
            self._hold(t)
            k += 1
        return k

    def _hold(self, t: float) -> None:
        """After tick time ``t``: if a --hold-at is due, wait until the launcher has
        announced the fault (or --hold-timeout), handling membership meanwhile."""
        due = [h for h in self.holds if h <= t]
        if not due:
            return
        self.holds = self.holds[len(due):]
        deadline = time.monotonic() + self.args.hold_timeout
        # until the fault is announced and every agent it started is alive: a process
        # takes a second or two of wall time to start, which must not be simulated time
        while (self.fault_t < due[-1] or self.awaited) and not self.stopping:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                what = ("no fault announced" if self.fault_t < due[-1] else
                        f"agents {sorted(self.awaited)} not alive")
                log.warning("t = %.1f s: %s after %g s; going on", t, what,
                            self.args.hold_timeout)
                self.awaited.clear()
                return
            try:
                self._handle(self.events.get(timeout=remaining))
            except queue.Empty:
                pass

    def run_realtime(self, total: int) -> int:
        events, world, dt = self.events, self.world, self.dt
        latest: dict[int, tuple[float, float, float]] = {}  # robot -> v, omega, wall time
        start = time.monotonic()
        k = 0
        while k < total and not self.stopping:
            t = k * dt
            if k and (k % INFO_EVERY_TICKS == 0 or self.frame_due(k)):
                self.publish_info()
            self.publish_sensing(k, t)
            began = time.monotonic()
            deadline = start + (k + 1) * dt
            while not self.stopping:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                try:
                    cmd = self._handle(events.get(timeout=remaining))
                except queue.Empty:
                    break
                if cmd is not None:
                    latest[cmd.robot] = (cmd.v, cmd.omega, time.monotonic())
            if self.stopping:
                break
            now = time.monotonic()
            cmds = {
                i: (v, w)
                for i, (v, w, seen) in latest.items()
                if i in self.live and now - seen <= self.args.cmd_timeout
            }
            waited_ms = (now - began) * 1000.0
            self.pub_tick.put(encode(Tick(t, k, sorted(self.live), waited_ms, k == total - 1,
                                          time.time_ns(), self.dropped, self.rejected)))
            world.step(cmds, dt)
            k += 1
        return k


def parse_kidnaps(specs: list[str], dt: float) -> dict[int, list[tuple[int, float, float]]]:
    """``ROBOT@T:DX,DY`` options by tick: {k: [(robot, dx, dy), ...]}; ValueError."""
    out: dict[int, list[tuple[int, float, float]]] = {}
    for spec in specs:
        try:
            robot_s, rest = spec.split("@", 1)
            t_s, move = rest.split(":", 1)
            dx_s, dy_s = move.split(",", 1)
            robot, t, dx, dy = int(robot_s), float(t_s), float(dx_s), float(dy_s)
        except ValueError:
            raise ValueError(f"bad --kidnap {spec!r}: use ROBOT@T:DX,DY") from None
        if robot < 0 or t < 0:
            raise ValueError(f"bad --kidnap {spec!r}: negative robot or time")
        out.setdefault(round(t / dt), []).append((robot, dx, dy))
    return out


def _check_args(args: argparse.Namespace) -> str | None:
    if args.robots < 1:
        return "--robots must be at least 1"
    if args.team is not None and not 1 <= args.team <= args.robots:
        return "--team must be between 1 and --robots"
    if not args.dt > 0 or not args.duration > 0:
        return "--dt and --duration must be positive"
    if not (math.isfinite(args.boot_s) and args.boot_s >= 0):
        return "--boot-s must be >= 0"
    turn_noise = args.odom_noise if args.odom_turn_noise is None else args.odom_turn_noise
    if min(args.odom_noise, turn_noise, args.cmd_timeout, args.startup_timeout, args.settle,
           args.hold_timeout) < 0:
        return ("--odom-noise, --odom-turn-noise, --cmd-timeout, --startup-timeout, --settle "
                "and --hold-timeout must be >= 0")
    if args.laser_noise < 0:
        return "--laser-noise must be >= 0"
    if not 0 <= args.scanners <= MAX_SCANNERS:
        return f"--scanners must be 0 (one per 10 m of edge) to {MAX_SCANNERS}"
    try:
        kidnaps = parse_kidnaps(args.kidnap, args.dt)
    except ValueError as exc:
        return str(exc)
    if any(r >= args.robots for moves in kidnaps.values() for r, _, _ in moves):
        return "--kidnap: no such robot"
    try:
        parse_start(args.start, args.team or args.robots)
    except ValueError as exc:
        return str(exc)
    return None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="btrack world: %(message)s")
    problem = _check_args(args)
    if problem:
        print(f"btrack world: {problem}", file=sys.stderr)
        return 2
    gmap = load_checked_map(args, "btrack world")
    if gmap is None:
        return 2
    lab = profile(args.sensors)
    if gmap.closed and (args.localization == "pf" or lab is not None):
        print("btrack world: a closed edge (a ring round a floe) has no laser's view round it"
              " yet: use --localization truth or odometry and --sensors ideal",
              file=sys.stderr)
        return 2
    try:
        change = changing_map(gmap, args.change, args.scale, args.seed)
    except ChangeError as exc:
        print(f"btrack world: {exc}", file=sys.stderr)
        return 2
    if change is not None and lab is not None:
        print("btrack world: --change: the lab sensors read a static map only, so far; "
              "use --sensors ideal", file=sys.stderr)
        return 2
    world = World(gmap, args.robots, args.start, args.seed, args.odom_noise, args.team,
                  odom_turn_noise=args.odom_turn_noise,
                  slip=Slip(lab, args.seed) if lab is not None else None, change=change)
    total = round(args.duration / args.dt)

    with bounded_session(options_from_args(args), "btrack world") as session:
        proc = WorldProcess(args, world, session)
        previous = {
            sig: signal.signal(sig, lambda *_: proc.stop())
            for sig in (signal.SIGTERM, signal.SIGINT)
        }
        try:
            if not proc.wait_for_team():
                return 0 if proc.stopping else 1
            # Without it, a state of tick 0 could be published before a neighbour's
            # subscription had reached its publisher: lost, and that neighbour's tick 1
            # would act on nothing, a run that depends on timing.
            time.sleep(args.settle)
            proc.publish_info()
            began = time.monotonic()
            run = proc.run_realtime if args.realtime else proc.run_lockstep
            ticks = run(total)
            wall = time.monotonic() - began
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        summary = {
            "ticks": ticks,
            "wall_s": round(wall, 3),
            "speedup": round(ticks * args.dt / wall, 1) if wall > 0 else None,
            "dropped": proc.dropped,
            "rejected": proc.rejected,
            "timeouts": proc.timeouts,
            "interrupted": proc.stopping,
        }
        print(json.dumps(summary), flush=True)
    return 0

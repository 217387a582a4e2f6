"""``btrack bridge hil-world``: the simulator's physics behind emulated devices.

For hardware-in-the-loop runs with no hardware: one emulated iRobot Create per robot
and one emulated SICK LMS 2xx, each on a pseudo-terminal (``DIR/createI``, ``DIR/lms``),
which the real bridge processes open. The wheel speeds the bridges command turn into
``simworld.world.World`` kinematics at ``--physics-hz`` on the wall clock; the World's
ice and algae sensing set each Create's cargo bay inputs (analog: ``ICE_ANALOG`` over
ice, ``WATER_ANALOG`` over water; digital input 0: algae) and its noisy odometry feeds
the Create's distance and angle counters; the LMS's ranges are the robots seen as
discs from the laser's pose. ``--faults P`` damages that fraction of the devices'
messages (garbage, a flipped bit, a cut) so the bridges must resynchronise.

What only a simulator can know it publishes itself, as ``btrack world`` does: ``Truth``
of every robot at each tick of the run's epoch grid (k = t // dt, the ticks the bridges
publish their Sense on), for the report, and with ``--localization truth`` a truth
``Pose`` too, so agents run as in ``btrack sim --localization truth`` (with ``pf`` the
localizer gives the poses, from the LMS bridge's scans, and the run waits for it);
``Tick`` and ``WorldInfo`` for the recorder and the report. The emulated LMS sees the
robots where they were at its sweep's middle, 13 ms before its telegram.
It waits for the whole team (and the recorder) like the world does, runs ``--duration``
wall seconds, ends with a done Tick, prints its counters as JSON and keeps the devices
plugged in until SIGTERM.
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import math
import queue
import sys
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

from hwbridge.common import add_epoch_arg, on_stop
from hwbridge.create.model import MODELS
from hwbridge.emulators.pty import CreateEmulator, Faults, LmsEmulator
from hwbridge.lms.model import ScanGeometry
from hwbridge.runclock import RunClock, tick_of
from simworld.shell import WorldShell, load_checked_map
from simworld.world import ROBOT_RADIUS_M, World, parse_start
from wire import Pose, Tick, Truth, encode
from wire.session import (
    add_session_args,
    bounded_session,
    declare_publisher,
    options_from_args,
)

log = logging.getLogger("btrack.hil")

ICE_ANALOG = 850  # what the upward IR sensor reads under ice (bright, near)
WATER_ANALOG = 120  # and under open sky / water
LASER_BEHIND_M = 1.0  # DESIGN.md: the laser 1 m behind the robots' start line
INFO_EVERY_S = 10.0
SWEEP_MIDDLE_S = 1.0 / 75.0  # half of two 75 Hz mirror turns (lms_bridge.TURNS)
HISTORY_STEPS = 8  # physics steps kept for it (at 100 Hz: 70 ms)
LINGER_S = 60.0  # after the run, keep the devices until SIGTERM (at most this long)


def laser_pose(world: World) -> tuple[float, float, float]:
    """DESIGN.md: 1 m behind the robots' start line, centred on the edge, facing it."""
    start_y = min(world.truth(i)[1] for i in range(world.n))
    return (0.5 * (world.map.edge_lo + world.map.edge_hi), start_y - LASER_BEHIND_M,
            math.pi / 2)


def scan_ranges(pose: tuple[float, float, float], bearings: np.ndarray,
                robots: list[tuple[float, float]], radius: float, range_max: float) -> list[float]:
    """Ranges from ``pose`` along each bearing to the nearest robot disc (or infinity)."""
    x, y, th = pose
    ang = th + bearings
    dx, dy = np.cos(ang), np.sin(ang)
    best = np.full(bearings.shape, np.inf)
    for cx, cy in robots:
        ox, oy = cx - x, cy - y
        along = dx * ox + dy * oy
        perp2 = ox * ox + oy * oy - along * along
        hit = (along > 0) & (perp2 <= radius * radius)
        dist = along - np.sqrt(np.clip(radius * radius - perp2, 0.0, None))
        best = np.where(hit & (dist < best), dist, best)
    best[best > range_max] = np.inf
    return best.tolist()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack bridge hil-world",
        description="Simulated physics behind emulated Creates and an emulated LMS on "
                    "pseudo-terminals, for hardware-in-the-loop runs without hardware.")
    p.add_argument("--dir", type=Path, required=True,
                   help="directory for the device names DIR/createI and DIR/lms")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--map", default="half-algae")
    p.add_argument("--scale", type=float, default=0.05)
    p.add_argument("--start", default="ahead:1")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--odom-noise", type=float, default=0.02)
    p.add_argument("--duration", type=float, default=300.0, help="wall seconds to run (300)")
    p.add_argument("--dt", type=float, default=0.1, help="tick period, s (0.1)")
    p.add_argument("--physics-hz", type=float, default=100.0)
    p.add_argument("--faults", type=float, default=0.0,
                   help="fraction of device messages damaged on purpose (0)")
    p.add_argument("--startup-timeout", type=float, default=90.0)
    p.add_argument("--wait-recorder", action="store_true")
    p.add_argument("--localization", choices=["truth", "pf"], default="truth",
                   help="truth: publish every robot's true Pose (agents on truth); pf: "
                        "only Truth for the report, the localizer gives the poses from "
                        "the LMS bridge's scans, and the run waits for it (truth)")
    add_epoch_arg(p)
    add_session_args(p)
    return p


class HilWorld(WorldShell):
    """The world shell (``simworld.shell``) around a ``World`` stepped on the wall clock
    behind emulated devices."""

    def __init__(self, args: argparse.Namespace, world: World, session: zenoh.Session) -> None:
        pf = args.localization == "pf"
        super().__init__(args, world, session, localization=args.localization, realtime=True,
                         localizer=pf)
        keys = self.keys
        self.lock = threading.Lock()  # the World, between physics and the laser thread
        self.spec = MODELS["create"]
        args.dir.mkdir(parents=True, exist_ok=True)
        f = args.faults
        self.creates = [
            CreateEmulator(args.dir / f"create{i}", self.spec,
                           Faults(garbage=f / 3, corrupt=f / 3, truncate=f / 3,
                                  seed=args.seed * 100 + i))
            for i in range(self.n)
        ]
        self.laser = laser_pose(world)
        self.geometry = ScanGeometry()
        self.bearings = np.array(self.geometry.bearings())
        self.lms = LmsEmulator(args.dir / "lms", self._ranges,
                               Faults(garbage=f / 3, corrupt=f / 3, truncate=f / 3,
                                      seed=args.seed * 100 + 99))
        self._sense_inputs()
        self.running = False
        self.dropped = 0
        self.pub_truth = declare_publisher(session, keys.truth())
        self.pub_pose = ([] if pf else
                         [declare_publisher(session, keys.pose(i)) for i in range(self.n)])
        # the robots' true poses over the last few physics steps, for the laser: the
        # emulated LMS measures as a real one does, over its sweep before its telegram
        self.history: collections.deque[tuple[float, list[tuple[float, float]]]] = (
            collections.deque(maxlen=HISTORY_STEPS))

    def _ranges(self) -> list[float]:
        """The robots as the laser saw them at its sweep's middle, half its two mirror
        turns (0.5 degrees interlaced at 75 Hz) before its telegram begins: the physics
        step nearest that time."""
        seen_at = time.monotonic() - SWEEP_MIDDLE_S
        with self.lock:
            robots = (min(self.history, key=lambda h: abs(h[0] - seen_at))[1] if self.history
                      else [self.world.truth(i)[:2] for i in range(self.n)])
        return scan_ranges(self.laser, self.bearings, robots, ROBOT_RADIUS_M,
                           self.geometry.range_max_m)

    def _sense_inputs(self) -> None:
        for i, emu in enumerate(self.creates):
            r = self.world.sense(i)
            with emu.lock:
                emu.device.analog = ICE_ANALOG if r.ice else WATER_ANALOG
                emu.device.digital = 1 if r.algae else 0

    def start_devices(self) -> None:
        for emu in self.creates:
            emu.start()
        self.lms.start()

    def stop_devices(self) -> None:
        for emu in (*self.creates, self.lms):
            emu.stop()

    def physics(self, dt: float) -> None:
        cmds = {}
        wb = self.spec.wheel_base_m
        for i, emu in enumerate(self.creates):
            with emu.lock:
                right, left = emu.device.wheel_speeds()
            cmds[i] = (0.5 * (right + left), (right - left) / wb)
        with self.lock:
            self.world.step(cmds, dt)
            self.history.append((time.monotonic(),
                                 [self.world.truth(i)[:2] for i in range(self.n)]))
        for i, emu in enumerate(self.creates):
            r = self.world.sense(i)
            with emu.lock:
                emu.device.add_motion(r.odom_dist_m, r.odom_dtheta)
        self._sense_inputs()

    def publish_poses(self, k: int) -> None:
        """Truth and the truth Pose of tick k, at the tick's time on the epoch's grid:
        the same instant the bridges sample their robots' Sense of tick k."""
        t = k * self.args.dt
        with self.lock:
            poses = [self.world.truth(i) for i in range(self.n)]
        self.pub_truth.put(encode(Truth.of_team(t, k, poses)))
        for i, (x, y, th) in enumerate(poses if self.pub_pose else ()):
            self.pub_pose[i].put(encode(Pose(t, k, i, x, y, th)))

    def respond(self) -> None:
        """Its own thread: membership events, off the physics loop."""
        while not self.stopping:
            try:
                self.membership(self.events.get(timeout=0.1))
            except queue.Empty:
                pass

    def run(self, clock: RunClock) -> dict[str, object]:
        a = self.args
        responder = threading.Thread(target=self.respond, daemon=True)
        responder.start()
        step = 1.0 / a.physics_hz
        began = last = time.monotonic()
        deadline_start = began + a.startup_timeout
        next_tick = next_info = end = 0.0
        k = ticks = 0
        done = False
        while not self.stopping:
            now = time.monotonic()
            while self.running and now >= next_tick:  # late: catch up, never skip
                # Step exactly to the tick's grid time first, so that Truth and Pose of
                # tick k are the robots' poses at t = k * dt even when this loop is late.
                if next_tick > last:
                    self.physics(next_tick - last)
                    last = next_tick
                done = now >= end
                self.publish_poses(k)
                self.pub_tick.put(encode(Tick(k * a.dt, k, sorted(self.live), 0.0, done,
                                              time.time_ns())))
                ticks += 1
                # The next tick on the epoch's grid. A late tick is still published: its
                # poses are exact (physics stepped to its grid time), only later.
                k += 1
                next_tick = clock.mono_at(k * a.dt)
                if done:
                    break
                if now >= next_info:
                    self.publish_info()
                    next_info += INFO_EVERY_S
            if ticks and done:
                break
            self.physics(now - last)
            last = now
            if not self.running:
                if self.ready():
                    self.running = True
                    k = tick_of(clock.t(), a.dt) + 1
                    next_tick = clock.mono_at(k * a.dt)
                    self.first_k = k  # the recorder knows the run's last tick by it
                    self.publish_info()
                    next_info, end = now + INFO_EVERY_S, now + a.duration
                elif now > deadline_start:
                    print(f"btrack bridge hil-world: {self.waiting_for()} not alive after "
                          f"{a.startup_timeout:g} s (live {sorted(self.live)})", file=sys.stderr)
                    return {"error": "startup timeout"}
            time.sleep(max(0.0, last + step - time.monotonic()))
        wall = time.monotonic() - began
        self.running = False
        return {
            "hil_world": True, "ticks": ticks, "wall_s": round(wall, 3), "dropped": self.dropped,
            "rejected": self.rejected,
            "create_frames": [e.frames for e in self.creates],
            "lms_scans": self.lms.scans,
            "faults_injected": sum(e.faults.injected for e in (*self.creates, self.lms)),
            "device_bytes_out": sum(e.bytes_out for e in (*self.creates, self.lms)),
            "device_bytes_in": sum(e.bytes_in for e in (*self.creates, self.lms)),
            "lms_bytes_out": self.lms.bytes_out,
            "interrupted": self.stopping,
        }


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="btrack bridge hil-world: %(message)s")
    if args.robots < 1 or not args.duration > 0 or not 0 <= args.faults < 1:
        print("btrack bridge hil-world: need --robots >= 1, --duration > 0, 0 <= --faults < 1",
              file=sys.stderr)
        return 2
    try:
        parse_start(args.start, args.robots)
    except ValueError as exc:
        print(f"btrack bridge hil-world: {exc}", file=sys.stderr)
        return 2
    gmap = load_checked_map(args, "btrack bridge hil-world")
    if gmap is None:
        return 2
    world = World(gmap, args.robots, args.start, args.seed, args.odom_noise)
    clock = RunClock(args.epoch)
    with bounded_session(options_from_args(args), "btrack bridge") as session:
        hil = HilWorld(args, world, session)

        on_stop(hil.stop)
        hil.start_devices()
        try:
            summary = hil.run(clock)
            print(json.dumps(summary), flush=True)
            # The devices stay plugged in until we are told to stop, so that the bridges
            # are stopped first and do not count a "lost port" at the end of the run.
            deadline = time.monotonic() + LINGER_S
            while not hil.stopping and time.monotonic() < deadline and "error" not in summary:
                time.sleep(0.05)
        finally:
            hil.stop_devices()
    return 1 if "error" in summary else 0

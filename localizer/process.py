"""``btrack localizer``: laser scans plus each robot's odometry in, one pose per robot
per scan out (thesis ch. 5, 6.1.5), as its own process.

It hears the scanners (``laser/scan``: one scan per scanner of the row and tick) and
every robot's sensing (``robot/*/sense``, for the odometry of the last period). Tick
k is processed once every scanner's scan k and the sensing of tick k of every robot
are in (or, if a robot's sensing is missing, when a
later scan arrives or after ``--sense-timeout`` wall seconds, with no motion for that
robot); then it publishes ``robot/I/pose`` of tick k for every robot, source ``pf``.
In lockstep simulation the agents wait for that pose, so the world's clock waits
for the localizer too. Malformed messages are counted and dropped. Zenoh callbacks
only enqueue; the filter runs on the main thread.
"""

from __future__ import annotations

import argparse
import json
import queue
import signal
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import zenoh

from localizer.core import Estimate, FilterConfig, Localizer, ScanGeometry
from localizer.timeline import OdometryTimeline, advance
from wire import DecodeError, Keys, Particles, Pose, Scan, Sense, decode, encode
from wire.messages import MAX_CLOUD
from wire.session import add_session_args, declare_publisher, open_session, options_from_args

KEEP_TICKS = 50  # pending ticks kept before the oldest is given up


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack localizer",
        description="Laser localisation: one particle filter per robot from the scanner's "
        "scans and each robot's odometry; publishes every robot's pose per scan.",
    )
    p.add_argument("--robots", type=int, required=True, help="team size (robot ids 0..N-1)")
    d = FilterConfig()
    p.add_argument("--particles", type=int, default=d.particles,
                   help=f"particles per robot ({d.particles})")
    p.add_argument("--meas-std", type=float, default=d.meas_std_m,
                   help=f"std of a measured centre, m ({d.meas_std_m})")
    p.add_argument("--radius", type=float, default=d.radius_m,
                   help=f"robot radius, m ({d.radius_m})")
    p.add_argument("--gate", type=float, default=d.gate_m,
                   help=f"largest distance from a prediction to its blob, m ({d.gate_m})")
    p.add_argument("--seed", type=int, default=1, help="seed of the filters' noise (1)")
    p.add_argument("--sensors", choices=["ideal", "lab"], default="ideal",
                   help="what the scans are like: ideal (the simulator's ideal laser, the "
                   "default) or lab (a real LMS 2xx: FilterConfig.lab(), median filter, "
                   "mixed pixels trimmed, the sweep's timing, partial blobs kept apart)")
    p.add_argument("--scanners", type=int, metavar="N",
                   help="scans per tick (the world's row of scanners); a scan of another "
                   "row is dropped (default: the first scan of each tick says)")
    p.add_argument("--clouds-every", type=int, default=0, metavar="N",
                   help="every N scans, also publish a sample of each robot's particles on "
                   "robot/I/particles, for the recording and viewers (0: never, the default)")
    p.add_argument("--cloud-size", type=int, default=200, metavar="M",
                   help=f"particles in each published sample (200, at most {MAX_CLOUD})")
    p.add_argument("--sense-timeout", type=float, default=0.5,
                   help="wall seconds to wait for a robot's sensing of a scanned tick (0.5)")
    p.add_argument("--timing", choices=["tick", "measured"], default="tick",
                   help="tick: one scan per control tick, on it (the simulator); measured: "
                   "scans at the laser's own rate, each at its measurement time (a real "
                   "LMS): the filter is moved to each scan's time by the odometry, and "
                   "every robot gets a pose on every sensing tick, the estimate carried "
                   "forward by its odometry (tick)")
    add_session_args(p)
    return p


class LocalizerNode:
    """The shell around a ``Localizer``: subscriptions, the per-tick buffer, publishing."""

    def __init__(self, session: zenoh.Session, keys: Keys, robots: int, config: FilterConfig,
                 seed: int, sense_timeout: float, clouds_every: int = 0, cloud_size: int = 200,
                 scanners: int | None = None):
        self.keys = keys
        self.n = robots
        self.core = Localizer(robots, config, seed=seed)
        self.sense_timeout = sense_timeout
        self.events: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()
        self.scans: dict[int, dict[int, Scan]] = {}  # tick -> scanner -> its scan
        self.senses: dict[int, dict[int, Sense]] = {}
        self.first_seen: dict[int, float] = {}
        self.last_k = -1
        self.dropped = 0
        self.scans_done = 0
        self.late = 0  # ticks processed without every robot's odometry
        self.update_s = 0.0
        self.stopping = False
        self.pub_pose = [declare_publisher(session, keys.pose(i)) for i in range(robots)]
        self.clouds_every, self.cloud_size = clouds_every, cloud_size
        self.scanners = scanners
        self.pub_cloud = ([declare_publisher(session, keys.particles(i)) for i in range(robots)]
                          if clouds_every else [])
        self.subs = [
            session.declare_subscriber(keys.scan(), self._on("scan")),
            session.declare_subscriber(keys.sense("*"), self._on("sense")),
        ]
        self.token = session.liveliness().declare_token(keys.alive_localizer())

    def _on(self, kind: str) -> Callable[[zenoh.Sample], None]:
        def callback(sample: zenoh.Sample) -> None:
            self.events.put((kind, (str(sample.key_expr), sample.payload.to_bytes())))
        return callback

    def stop(self) -> None:
        self.stopping = True
        self.events.put(("stop", None))

    def _drop(self, key: str, why: str) -> None:
        self.dropped += 1
        if self.dropped <= 20 or self.dropped % 1000 == 0:
            print(f"localizer: dropped message #{self.dropped} on {key}: {why}",
                  file=sys.stderr, flush=True)

    def _handle(self, kind: str, data: tuple[str, bytes]) -> None:
        key, payload = data
        try:
            if kind == "scan":
                scan = decode(Scan, payload)
                if self.scanners is not None and scan.scanners != self.scanners:
                    raise DecodeError(f"scan from scanner {scan.scanner} of {scan.scanners}; "
                                      f"this team has {self.scanners}")
                if scan.k > self.last_k:
                    row = self.scans.setdefault(scan.k, {})
                    if row and next(iter(row.values())).scanners != scan.scanners:
                        raise DecodeError(f"scan of tick {scan.k} from scanner {scan.scanner} "
                                          f"of {scan.scanners}, its others of "
                                          f"{next(iter(row.values())).scanners}")
                    row[scan.scanner] = scan
                    self.first_seen.setdefault(scan.k, time.monotonic())
            else:
                sense = decode(Sense, payload)
                if sense.robot != Keys.robot_of(key):
                    raise DecodeError(f"sense of robot {sense.robot} on {key}")
                if sense.robot >= self.n:
                    raise DecodeError(f"robot {sense.robot} outside a team of {self.n}")
                if sense.k > self.last_k:
                    self.senses.setdefault(sense.k, {})[sense.robot] = sense
        except DecodeError as exc:
            self._drop(key, str(exc))

    def _ready(self, now: float) -> int | None:
        """The oldest scanned tick that can be processed now, or None: every scanner's
        scan and every robot's sensing in, or a later tick's scan, or the timeout."""
        if not self.scans:
            return None
        k = min(self.scans)
        row = self.scans[k]
        complete = len(row) == next(iter(row.values())).scanners
        if complete and len(self.senses.get(k, {})) == self.n:
            return k
        if len(self.scans) > 1 or now - self.first_seen[k] >= self.sense_timeout:
            return k  # a scan or a robot's sensing went missing: go on without it
        return None

    def process(self, k: int) -> None:
        row = self.scans.pop(k)
        scans = [row[j] for j in sorted(row)]
        self.first_seen.pop(k, None)
        senses = self.senses.pop(k, {})
        if len(senses) < self.n:
            self.late += 1
        dist = np.zeros(self.n)
        dtheta = np.zeros(self.n)
        for i, s in senses.items():
            dist[i], dtheta[i] = s.odom_dist_m, s.odom_dtheta
        began = time.perf_counter()
        views = [(np.asarray(s.ranges), ScanGeometry.of(s)) for s in scans]
        dt = next(iter(senses.values())).dt if senses else 0.0
        estimates = self.core.step_scans(views, dist, dtheta, dt)
        scan = scans[0]
        self.update_s += time.perf_counter() - began
        for i, e in enumerate(estimates):
            pose = Pose(scan.t, k, i, e.x, e.y, e.theta, [e.var_x, e.var_y, e.var_theta], "pf")
            self.pub_pose[i].put(encode(pose))
        if self.clouds_every and k % self.clouds_every == 0:  # after the poses: off the path
            for i, (x, y) in enumerate(self.core.cloud(self.cloud_size)):
                self.pub_cloud[i].put(encode(Particles(scan.t, k, i, x, y)))
        self.last_k = k
        self.scans_done += 1
        for old in [kk for kk in self.senses if kk <= k]:
            del self.senses[old]
        while len(self.scans) > KEEP_TICKS:
            self.scans.pop(min(self.scans))

    POLL_S = 0.05  # the longest the loop waits for a message before it looks again

    def run(self) -> None:
        while not self.stopping:
            try:
                kind, data = self.events.get(timeout=self.POLL_S)
                if kind == "stop":
                    break
                self._handle(kind, data)
                while True:  # drain what is already queued before deciding
                    kind, data = self.events.get_nowait()
                    if kind == "stop":
                        return
                    self._handle(kind, data)
            except queue.Empty:
                pass
            self.step(time.monotonic())

    def step(self, now: float) -> None:
        """Process every tick that is ready."""
        while (k := self._ready(now)) is not None:
            self.process(k)

    def close(self) -> None:
        self.token.undeclare()


class MeasuredTimingNode(LocalizerNode):
    """``--timing measured``: scans come when the laser sends them, stamped with their
    measurement time, not one per tick (``localizer.timeline``). A scan is taken in
    once every robot's odometry up to its time is in (or after ``sense_timeout``),
    scans in time order; a pose goes out for every tick whose sensing is in, from the
    latest estimate carried forward by the odometry since its scan."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.dt: float | None = None
        self.timeline: OdometryTimeline | None = None
        self.pending: list[tuple[Scan, float]] = []  # not yet taken in, by time: (scan, came)
        self.estimates: list[Estimate] | None = None
        # tick -> (when its first sensing came, the robots whose sensing is in)
        self.sensed: dict[int, tuple[float, set[int]]] = {}
        self.last_pose_k = -1
        self.stale_scans = 0  # measured before a scan already taken in

    def _handle(self, kind: str, data: tuple[str, bytes]) -> None:
        key, payload = data
        try:
            if kind == "scan":
                scan = decode(Scan, payload)
                if scan.scanners != 1:
                    raise DecodeError("measured timing takes one scanner")
                self.pending.append((scan, time.monotonic()))
                self.pending.sort(key=lambda p: p[0].t)
                return
            sense = decode(Sense, payload)
            if sense.robot != Keys.robot_of(key):
                raise DecodeError(f"sense of robot {sense.robot} on {key}")
            if sense.robot >= self.n:
                raise DecodeError(f"robot {sense.robot} outside a team of {self.n}")
            if self.timeline is None:  # the filter starts at the first sensing's period
                self.dt = sense.dt
                self.timeline = OdometryTimeline(self.n, at=float(sense.k - 1))
            taken = self.timeline.add(sense.k, sense.robot, sense.odom_dist_m,
                                      sense.odom_dtheta)
            if taken and sense.k > self.last_pose_k:  # else too late for its tick's pose
                self.sensed.setdefault(sense.k, (time.monotonic(), set()))[1].add(sense.robot)
        except DecodeError as exc:
            self._drop(key, str(exc))

    POLL_S = 0.02  # poses are due on every sensing tick, 0.1 s apart

    def step(self, now: float) -> None:
        tl, dt = self.timeline, self.dt
        if tl is None or dt is None:
            return
        while self.pending:
            scan, came = self.pending[0]
            until = scan.t / dt
            if until < tl.at:
                self.pending.pop(0)
                self.stale_scans += 1
                continue
            if not tl.complete(until) and now - came < self.sense_timeout:
                break
            self.pending.pop(0)
            dist, dtheta = tl.take(until)
            began = time.perf_counter()
            self.estimates = self.core.step_scans(
                [(np.asarray(scan.ranges), ScanGeometry.of(scan))], dist, dtheta)
            self.update_s += time.perf_counter() - began
            self.scans_done += 1
        for k in sorted(self.sensed):
            came, robots = self.sensed[k]
            whole = len(robots) == self.n
            if not whole and now - came < self.sense_timeout:
                break
            if not whole:
                self.late += 1
            self._pose(k)

    def _pose(self, k: int) -> None:
        tl, dt = self.timeline, self.dt
        assert tl is not None and dt is not None
        self.sensed.pop(k, None)
        self.last_pose_k = k
        if self.estimates is None:
            return  # no scan yet: no pose
        motions = tl.ahead(float(k))
        for i, e in enumerate(self.estimates):
            x, y, theta = advance(e.x, e.y, e.theta, [(float(m[i, 0]), float(m[i, 1]))
                                                      for m in motions])
            self.pub_pose[i].put(encode(Pose(k * dt, k, i, x, y, theta,
                                             [e.var_x, e.var_y, e.var_theta], "pf")))



def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.robots < 1:
        print("btrack localizer: --robots must be at least 1", file=sys.stderr)
        return 2
    try:
        make = FilterConfig.lab if args.sensors == "lab" else FilterConfig
        config = make(particles=args.particles, meas_std_m=args.meas_std,
                      radius_m=args.radius, gate_m=args.gate)
    except ValueError as exc:
        print(f"btrack localizer: {exc}", file=sys.stderr)
        return 2
    if args.clouds_every < 0 or not 1 <= args.cloud_size <= MAX_CLOUD:
        print(f"btrack localizer: --clouds-every must be >= 0 and --cloud-size 1 to "
              f"{MAX_CLOUD}", file=sys.stderr)
        return 2
    opts = options_from_args(args)
    with open_session(opts) as session:
        cls = MeasuredTimingNode if args.timing == "measured" else LocalizerNode
        node = cls(session, Keys(opts.ns), args.robots, config, args.seed,
                   args.sense_timeout, args.clouds_every, args.cloud_size, args.scanners)
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: node.stop())
        try:
            node.run()
        finally:
            node.close()
            mean_ms = 1000.0 * node.update_s / node.scans_done if node.scans_done else None
            print(json.dumps({
                "localizer": True, "scans": node.scans_done, "dropped": node.dropped,
                "late": node.late, "resampled": node.core.resampled,
                "reseeded": node.core.reseeded, "timing": args.timing,
                "stale_scans": getattr(node, "stale_scans", 0),
                "update_ms_mean": None if mean_ms is None else round(mean_ms, 3),
            }), flush=True)
    return 0

"""Message types on the bus. Every message carries its simulation (or wall) time ``t``
and tick ``k``; nothing downstream reads a clock of its own.

Field types are checked on decode by ``wire.codec``; each class's ``check`` adds the
range rules (a boundary outside the edge, a phase outside [0, 2 pi), ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

TWO_PI = 2.0 * math.pi
MAX_SCANNERS = 16  # laser scanners watching one team
MAX_CLOUD = 2000  # particles of one robot's cloud in one message


class InvalidMessage(ValueError):
    """A message whose fields are well typed but out of range."""


def _require(cond: bool, why: str) -> None:
    if not cond:
        raise InvalidMessage(why)


@dataclass(frozen=True)
class Sense:
    """What robot ``robot``'s own sensors report at tick ``k`` (world/bridge -> agent)."""

    t: float
    k: int
    robot: int
    ice: bool  # the upward sensor sees ice overhead
    algae: bool  # the algae sensor sees algae overhead
    odom_dist_m: float  # distance driven since the previous tick (odometry)
    odom_dtheta: float  # heading change since the previous tick (odometry), rad
    edge_lo: float  # s_0 of the whole edge, m
    edge_hi: float  # s_n of the whole edge, m
    dt: float  # control period, s
    # The robot's own pose (x, y, theta) when the source of this Sense also gives it
    # (the simulator's truth or odometry): one message per robot and tick instead of a
    # Sense and a Pose. Empty when the pose comes on its own (a localizer's Pose).
    pose: list[float] = field(default_factory=list)
    pose_source: str = ""  # truth | odometry, with a pose
    # The edge is closed (issue 18: a ring round a floe): s is periodic, of length
    # edge_hi - edge_lo; the contour comes in WorldInfo.
    closed: bool = False

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.robot >= 0, "negative t, k or robot")
        _require(self.edge_lo < self.edge_hi, "edge_lo must be below edge_hi")
        _require(self.dt > 0, "dt must be positive")
        if self.pose or self.pose_source:
            _require(len(self.pose) == 3, "pose: x, y and theta")
            _require(self.pose_source in ("truth", "odometry"),
                     f"pose_source must be truth or odometry, not {self.pose_source!r}")


@dataclass(frozen=True)
class Pose:
    """An estimate of robot ``robot``'s pose (localizer or world -> agent)."""

    t: float
    k: int
    robot: int
    x: float
    y: float
    theta: float
    cov: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # var x, y, theta
    source: str = "truth"  # truth | odometry | pf

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.robot >= 0, "negative t, k or robot")
        _require(len(self.cov) == 3 and all(c >= 0 for c in self.cov), "cov: three variances")
        _require(self.source in ("truth", "odometry", "pf"), f"unknown source {self.source!r}")


@dataclass(frozen=True)
class Scan:
    """One sweep of the laser range finder (world/bridge -> localizer), SICK LMS 2xx
    geometry by default: 361 ranges from ``angle_min`` in steps of ``angle_step``
    (radians, counter-clockwise, relative to the scanner's heading). A beam that
    sees nothing reads ``range_max``. The scanner's pose in the world frame is part
    of the message, so the localizer needs no map of its own (thesis 6.1.5). A team
    watched by a row of scanners gets one Scan per scanner and tick, ``scanner`` of
    ``scanners``, all on the one key."""

    t: float
    k: int
    ranges: list[float]  # m, one per beam
    scanner_x: float
    scanner_y: float
    scanner_theta: float  # where the scanner faces (its beam at angle 0), rad
    angle_min: float = -0.5 * math.pi
    angle_step: float = math.pi / 360.0
    range_max: float = 8.0
    scanner: int = 0  # which scanner of the row
    scanners: int = 1  # how many scans each tick has

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0, "negative t or k")
        _require(0 <= self.scanner < self.scanners <= MAX_SCANNERS,
                 f"scanner {self.scanner} of {self.scanners} (at most {MAX_SCANNERS})")
        _require(1 <= len(self.ranges) <= 4096, "ranges: 1 to 4096 beams")
        _require(self.angle_step > 0 and self.range_max > 0, "bad angle_step or range_max")
        _require(
            all(0.0 <= r <= self.range_max for r in self.ranges), "range outside [0, range_max]"
        )


@dataclass(frozen=True)
class Truth:
    """Ground truth poses of every simulated robot at tick ``k``, one message per tick
    (world -> recorder only): ``robots[j]`` is at (``x[j]``, ``y[j]``, ``theta[j]``)."""

    t: float
    k: int
    robots: list[int]
    x: list[float]
    y: list[float]
    theta: list[float]

    @classmethod
    def of_team(cls, t: float, k: int, poses: list[tuple[float, float, float]]) -> Truth:
        """The message for robots 0..n-1 at the poses (x, y, theta) given in id order."""
        return cls(t, k, list(range(len(poses))), [p[0] for p in poses],
                   [p[1] for p in poses], [p[2] for p in poses])

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0, "negative t or k")
        n = len(self.robots)
        _require(len(self.x) == n and len(self.y) == n and len(self.theta) == n,
                 "robots, x, y and theta: one entry per robot")
        _require(all(r >= 0 for r in self.robots) and len(set(self.robots)) == n,
                 "robot ids: distinct and non-negative")


@dataclass(frozen=True)
class Particles:
    """A sample of one robot's particle cloud after scan ``k`` (localizer -> recorder
    and viewers, only when asked for: ``btrack localizer --clouds-every``): particle
    j at (``x[j]``, ``y[j]``), drawn evenly from the filter's particles."""

    t: float
    k: int
    robot: int
    x: list[float]
    y: list[float]

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.robot >= 0, "negative t, k or robot")
        _require(len(self.x) == len(self.y) <= MAX_CLOUD, f"x and y: as long as each other, "
                 f"at most {MAX_CLOUD} particles")


@dataclass(frozen=True)
class Cmd:
    """Velocity command for robot ``robot`` at tick ``k`` (agent -> world/bridge)."""

    t: float
    k: int
    robot: int
    v: float  # forward speed, m/s
    omega: float  # turn rate, rad/s

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.robot >= 0, "negative t, k or robot")
        _require(abs(self.v) <= 10.0 and abs(self.omega) <= 100.0, "command out of range")


MAX_CYCLE_S = 1e5  # no team cycle (or pass) is longer: a day
MAX_PASSES = 10_000
# A ring's arcs are in each robot's own frame of s, continuous in time, so they may
# leave [edge_lo, edge_hi) by whole turns; by no more than this many.
MAX_TURNS = 1000
MAX_CONTOUR = 100_000  # vertices of a closed edge in WorldInfo, at most


@dataclass(frozen=True)
class AgentState:
    """What agent ``robot`` tells its neighbours after tick ``k``: its segment
    [lo, hi], phase, desired phase and workload (thesis ch. 3-4)."""

    t: float
    k: int
    robot: int
    lo: float  # s_i, m
    hi: float  # s_{i+1}, m
    phase: float  # phi_i in [0, 2 pi), position-based (eq. 3.1)
    phase_des: float  # phi_des,i in [0, 2 pi)
    workload: float  # Psi_i = d_a,i * (s_{i+1} - s_i), m^2
    depth_avg: float  # d_a,i, m
    direction: int  # +1 travelling towards hi, -1 towards lo
    lower: int  # id of the lower neighbour, -1 if none
    upper: int  # id of the upper neighbour, -1 if none
    edge_lo: float
    edge_hi: float
    dropped: int = 0  # malformed messages this agent has counted and dropped so far
    # well-formed neighbour states it refused as implausible so far (agent.plausible)
    rejected: int = 0
    # phi_des unwrapped, rad: the team's count of sweeps, which sets the grid of pass
    # lines every robot shares; a robot takes its lower neighbour's
    turns: float = 0.0
    # The depths (m) it measured of the 0.1 m bins (indices from edge_lo) near its two
    # ends: a neighbour uses them for bins it has not measured itself.
    end_bins: list[int] = field(default_factory=list)
    end_depths: list[float] = field(default_factory=list)
    # The team's decision it follows (agent.team): the common cycle, s, and the passes
    # per sweep; 0 for none yet. A robot takes its lower neighbour's.
    cycle_s: float = 0.0
    passes: int = 0
    # Chain maxima of every robot's pass need (s) and segment length (m), over the
    # robots at or below the sender and at or above it; 0 for none yet.
    need_below: float = 0.0
    need_above: float = 0.0
    span_below: float = 0.0
    span_above: float = 0.0
    # On a closed edge (a ring): lo and hi are in the sender's own frame of s (its arc,
    # continuous in time: it may leave [edge_lo, edge_hi) by whole turns of the edge's
    # length), and so are its end_bins (bins of the ring's depth map, from s = 0).
    closed: bool = False

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.robot >= 0, "negative t, k or robot")
        _require(0.0 <= self.cycle_s <= MAX_CYCLE_S, "cycle_s outside [0, 1e5] s")
        _require(0 <= self.passes <= MAX_PASSES, "passes outside [0, 10000]")
        _require(0.0 <= self.need_below <= MAX_CYCLE_S and 0.0 <= self.need_above <= MAX_CYCLE_S,
                 "pass need outside [0, 1e5] s")
        span = self.edge_hi - self.edge_lo
        _require(0.0 <= self.span_below <= span and 0.0 <= self.span_above <= span,
                 "segment span outside [0, the edge's length]")
        _require(self.dropped >= 0 and self.rejected >= 0, "negative dropped or rejected count")
        _require(len(self.end_bins) == len(self.end_depths),
                 "end_bins and end_depths must be as long as each other")
        _require(all(d >= 0 for d in self.end_depths), "negative depth")
        if self.closed:
            turns = MAX_TURNS * span
            _require(self.lo < self.hi <= self.lo + span, "an arc longer than the ring")
            _require(self.edge_lo - turns <= self.lo and self.hi <= self.edge_hi + turns,
                     f"an arc more than {MAX_TURNS} turns off the ring")
        else:
            _require(self.edge_lo <= self.lo < self.hi <= self.edge_hi,
                     "boundaries outside the edge")
        _require(0.0 <= self.phase < TWO_PI, "phase outside [0, 2 pi)")
        _require(0.0 <= self.phase_des < TWO_PI, "phase_des outside [0, 2 pi)")
        _require(self.workload >= 0 and self.depth_avg >= 0, "negative workload or depth")
        _require(self.direction in (-1, 1), "direction must be +1 or -1")
        _require(self.lower >= -1 and self.upper >= -1, "neighbour ids must be >= -1")


@dataclass(frozen=True)
class Tick:
    """The world's clock: tick ``k`` at time ``t`` was stepped with these live agents."""

    t: float
    k: int
    live: list[int]
    waited_ms: float = 0.0  # wall time spent waiting for commands
    done: bool = False  # the last tick of the run
    # the world's wall clock (ns since the epoch) when it published the tick; 0 if not
    # given. Speed and wall-time delays are measured on it, not on when a (possibly
    # lagging) recorder took the message.
    wall_ns: int = 0
    # the world's counts so far of the input it dropped as malformed and refused as
    # implausible (tokens of robots it does not have)
    dropped: int = 0
    rejected: int = 0

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.wall_ns >= 0, "negative t, k or wall_ns")
        _require(self.dropped >= 0 and self.rejected >= 0, "negative dropped or rejected")


@dataclass(frozen=True)
class Progress:
    """How far a run has got, as recorded (the recorder's answer to a query, for
    progress lines): the latest Tick; and the phase and workload of each robot with a
    state of the newest tick all current robots have published (``states_t``, its
    time; -1 without one), as their agents published them. The two can be far apart:
    under load, the recorder hears the world's one link behind the agents' many."""

    t: float
    k: int
    live: list[int]
    wall_ns: int  # the latest Tick's
    done: bool
    robots: list[int]
    phase: list[float]
    workload: list[float]
    states_t: float = -1.0

    def check(self) -> None:
        _require(self.t >= 0 and self.k >= 0 and self.wall_ns >= 0, "negative t, k or wall_ns")
        _require(len(self.phase) == len(self.robots) == len(self.workload),
                 "robots, phase and workload: one entry per robot")
        _require(self.states_t >= 0 or (self.states_t == -1.0 and not self.robots),
                 "states_t: the states' time, or -1 without states")


@dataclass(frozen=True)
class WorldInfo:
    """The scenario, for the recorder and reports: edge, true patrol depth per bin,
    run parameters. Published by the world at start and every few seconds."""

    map: str
    start: str
    robots: int
    localization: str
    seed: int
    duration_s: float
    dt: float
    edge_lo: float
    edge_hi: float
    bin_m: float
    patrol_depth: list[float]  # true patrol depth per bin from edge_lo, m
    robot_radius: float
    min_depth: float
    margin_out: float
    realtime: bool = False
    odom_noise: float = 0.02  # odometry std, fraction of each step's distance
    odom_turn_noise: float = 0.02  # and of each step's turn
    # the local edge's y per bin from edge_lo (the bins of patrol_depth), m; empty for a
    # straight edge at y = 0, as every recording made before the field existed
    edge_y: list[float] = field(default_factory=list)
    # the run's first tick: 0 in simulation; the hardware loop's ticks count from the
    # run's epoch (as its bridges' do), so it begins at the tick its team was up by, and
    # its last is first_k + duration_s / dt - 1
    first_k: int = 0
    # A map that changes during the run (issue 18): the changes as ``--change`` gave
    # them ("" for a static map), their windows flat [t0, t1, t0, t1, ...] in s, and the
    # simulated time from which this message's patrol_depth is the true one. The world
    # sends it again at every frame of a change (simworld.change.FRAME_EVERY_S and at a
    # window's ends); between two frames the true depth is the line between them.
    change: str = ""
    change_windows: list[float] = field(default_factory=list)
    depth_t: float = 0.0
    # A closed edge (issue 18: an island's contour, a ring of robots): ``contour`` its
    # vertices flat [x0, y0, x1, y1, ...] (m), counterclockwise with the ice on the
    # left, s = 0 at the first; edge_lo is 0, edge_hi its length, and patrol_depth is
    # per bin of bin_m round it from s = 0 (a whole number of bins make the ring). An
    # agent builds its edge frame (agent.edgeframe.ClosedEdge) from it.
    closed: bool = False
    contour: list[float] = field(default_factory=list)

    def check(self) -> None:
        _require(self.edge_lo < self.edge_hi and self.bin_m > 0, "bad edge or bin")
        if self.closed:
            _require(6 <= len(self.contour) <= 2 * MAX_CONTOUR and len(self.contour) % 2 == 0,
                     f"contour: 3 to {MAX_CONTOUR} vertices, x and y each")
        else:
            _require(not self.contour, "a contour on an open edge")
        w = self.change_windows
        _require(len(w) % 2 == 0 and all(a <= b for a, b in zip(w, w[1:], strict=False))
                 and all(w[i] < w[i + 1] for i in range(0, len(w), 2))
                 and all(v >= 0 for v in w), "change_windows: ordered [t0, t1, ...] pairs")
        _require(self.depth_t >= 0, "negative depth_t")
        _require(all(d >= 0 for d in self.patrol_depth), "negative patrol depth")
        _require(self.robots >= 1 and self.dt > 0, "bad robots or dt")
        _require(self.first_k >= 0, "negative first tick")
        if self.edge_y:
            _require(len(self.edge_y) == len(self.patrol_depth),
                     "edge_y: one entry per patrol_depth bin")
            _require(all(math.isfinite(y) for y in self.edge_y), "edge_y: not finite")


FAULT_KINDS = ("kill", "restart", "freeze", "thaw", "join")


@dataclass(frozen=True)
class Fault:
    """A fault injected into the run (launcher -> recorder): at simulation time ``t``
    agent ``agent`` was killed (SIGKILL), restarted, frozen (SIGSTOP), thawed
    (SIGCONT) or joined the team for the first time."""

    t: float
    kind: str
    agent: int
    pid: int = 0  # the process the signal went to, or the new process
    wall_ns: int = 0  # the launcher's wall clock when it acted (for detection delays)

    def check(self) -> None:
        _require(self.t >= 0 and self.agent >= 0 and self.pid >= 0 and self.wall_ns >= 0,
                 "negative t, agent, pid or wall time")
        _require(self.kind in FAULT_KINDS, f"unknown fault kind {self.kind!r}")


ALL_TYPES = (Sense, Pose, Scan, Truth, Cmd, AgentState, Tick, WorldInfo, Fault, Particles)

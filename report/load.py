"""Read a run.mcap (as written by the recorder) into plain numpy arrays."""

from __future__ import annotations

import dataclasses
import json
import re
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel, Footer, Message
from mcap.stream_reader import StreamReader

from wire.codec import DecodeError, from_record
from wire.keys import parse_path
from wire.messages import AgentState, Fault, Pose, Sense, Tick, WorldInfo
from wire.messages import Truth as WireTruth

STATE_FIELDS = ("t", "lo", "hi", "phase", "phase_des", "workload", "depth_avg", "direction",
                "lower", "upper", "cycle_s")
TRUTH_FIELDS = ("t", "x", "y", "theta")
ODOM_FIELDS = ("t", "odom_dist_m", "odom_dtheta")


_LEGACY_TRUTH = re.compile(r"^robot/[0-9]+/truth$")
_READ = (Tick, Fault, WireTruth, AgentState, Pose, Sense, WorldInfo)  # what the report reads


class LoadError(Exception):
    """The recording is missing or cannot be read."""


@dataclass
class Truth:
    """Ground-truth track of one robot, sorted by time."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray


@dataclass
class States:
    """What one agent published (its AgentState messages), sorted by time."""

    t: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    phase: np.ndarray
    phase_des: np.ndarray
    workload: np.ndarray
    depth_avg: np.ndarray
    direction: np.ndarray
    lower: np.ndarray  # the neighbour ids it named, -1 for none
    upper: np.ndarray
    cycle_s: np.ndarray  # the team's cycle it followed


@dataclass
class RunData:
    info: dict[str, Any]  # the last WorldInfo, {} if none was recorded
    tick_t: np.ndarray  # simulation time of each tick
    tick_log_ns: np.ndarray  # wall clock (ns) of each tick: the world's, else the recorder's
    # the recorder's wall clock (ns) when it took each tick off its channel: less
    # tick_log_ns, how far the recording lagged behind the world (0 if the world gave none)
    tick_recorded_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    tick_live: list[list[int]] = field(default_factory=list)  # the world's live agents
    faults: list[dict[str, Any]] = field(default_factory=list)  # Fault messages, by time
    truth: dict[int, Truth] = field(default_factory=dict)
    states: dict[int, States] = field(default_factory=dict)
    invalid: int = 0
    alive: dict[int, list[tuple[int, bool]]] = field(default_factory=dict)  # (log ns, alive)
    poses: dict[int, Truth] = field(default_factory=dict)  # the poses the agents were given
    odometry: dict[int, np.ndarray] = field(default_factory=dict)  # rows t, dist, dtheta
    # the edge's ends as the agents published them (a run with no world has no WorldInfo)
    agents_edge: tuple[float, float] | None = None
    # why the file ends early (a recorder killed before it wrote the summary); "" when
    # the file is whole
    cut_short: str = ""
    # well-formed messages the recorder refused as implausible, by topic (not measured)
    rejected: dict[str, int] = field(default_factory=dict)
    # what each part counted as dropped (malformed) and rejected (implausible): the
    # recorder by topic, each agent (its last state's counts) and the world (its last tick's)
    refused: dict[str, Any] = field(default_factory=dict)
    # a map that changes (WorldInfo.change_windows): the true patrol depth of every
    # WorldInfo, (depth_t, patrol_depth) by time, one per depth_t; empty for a static map
    depth_frames: list[tuple[float, list[float]]] = field(default_factory=list)

    @property
    def robot_ids(self) -> list[int]:
        return sorted(set(self.truth) | set(self.states))

    @property
    def positions_from(self) -> str:
        """Where the measures take the robots' positions from: "truth" (the simulator's)
        when the recording has it, else "poses" (the poses the agents were given: on
        hardware, the localizer's), else "none"."""
        return "truth" if self.truth else "poses" if self.poses else "none"

    @property
    def positions(self) -> dict[int, Truth]:
        """Each robot's track for the measures, from ``positions_from``."""
        return self.truth if self.truth else self.poses

    @property
    def edge(self) -> tuple[float, float] | None:
        """The edge's ends: the world's, else the agents'."""
        if "edge_lo" in self.info and "edge_hi" in self.info:
            return float(self.info["edge_lo"]), float(self.info["edge_hi"])
        return self.agents_edge


def _columns(rows: list[tuple[float, ...]], names: tuple[str, ...]) -> dict[str, np.ndarray]:
    arr = np.asarray(rows, dtype=float).reshape(-1, len(names))
    arr = arr[np.argsort(arr[:, 0], kind="stable")]
    return {name: arr[:, j].copy() for j, name in enumerate(names)}


def _one_of_each_time(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Of one robot's states sorted by time, one of each time. A second state of the
    same tick is a forgery or a fault (an agent sends one a tick), and which one the
    recorder heard first depends on timing (a forgery sent ahead of its tick comes
    first, but a lagging recorder may hear the true one first), so the one kept is the
    one whose boundaries lie nearest those of the robot's nearest single states before
    and after it; the last one where there are none."""
    t = cols["t"]
    if t.size < 2 or not (t[1:] == t[:-1]).any():
        return cols
    starts = np.flatnonzero(np.concatenate([[True], t[1:] != t[:-1]]))
    ends = np.append(starts[1:], t.size)
    single = ends - starts == 1
    lo, hi = cols["lo"], cols["hi"]
    keep = []
    for g, (a, z) in enumerate(zip(starts, ends, strict=True)):
        if z - a == 1:
            keep.append(a)
            continue
        before = np.flatnonzero(single[:g])
        after = np.flatnonzero(single[g + 1:])
        near = ([starts[before[-1]]] if before.size else []) + (
            [starts[g + 1 + after[0]]] if after.size else [])
        if not near:
            keep.append(z - 1)
            continue
        off = [sum(abs(lo[r] - lo[n]) + abs(hi[r] - hi[n]) for n in near) for r in range(a, z)]
        keep.append(a + int(np.argmin(off)))
    return {name: arr[keep] for name, arr in cols.items()}


def _messages(stream: BinaryIO, cut: list[str]) -> Iterator[tuple[Channel, Message]]:
    """Every message of the MCAP ``stream`` with its channel, in file order. A file
    without its summary (the recorder was killed: no footer, perhaps half a chunk at the
    end) is read record by record as far as it is whole, and the damage is noted in
    ``cut``."""
    reader = make_reader(stream)
    try:
        summary = reader.get_summary()
    except Exception:  # no footer, or a damaged one: read it as a stream
        summary = None
    if summary is not None:
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            yield channel, message
        return
    stream.seek(0)
    channels: dict[int, Channel] = {}
    try:
        for record in StreamReader(stream, skip_magic=False, emit_chunks=False).records:
            if isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message) and record.channel_id in channels:
                yield channels[record.channel_id], record
            elif isinstance(record, Footer):
                return  # a whole file after all, without an index
        end = "at the end of the file"
    except EndOfFile:
        end = "in a record cut off"
    except Exception as exc:  # the first damaged record: the end of the data
        end = f"in a damaged record ({type(exc).__name__})"
    cut.append(f"the file has no summary (its recorder did not finish it) and its data "
               f"end {end}")


def load_run(path: str | Path) -> RunData:
    """Load ``path`` (a run.mcap, or a directory holding one); raise ``LoadError``."""
    path = Path(path)
    if path.is_dir():
        path = path / "run.mcap"
    if not path.is_file():
        raise LoadError(f"no recording at {path}")
    info: dict[str, Any] = {}
    ticks: list[tuple[float, int, int]] = []
    live: list[list[int]] = []
    faults: list[dict[str, Any]] = []
    truth: dict[int, list[tuple[float, ...]]] = defaultdict(list)
    states: dict[int, list[tuple[float, ...]]] = defaultdict(list)
    alive: dict[int, list[tuple[int, bool]]] = defaultdict(list)
    poses: dict[int, list[tuple[float, ...]]] = defaultdict(list)
    odometry: dict[int, list[tuple[float, ...]]] = defaultdict(list)
    invalid = 0
    rejected: dict[str, int] = {}
    agent_counts: dict[int, tuple[int, int]] = {}
    world_counts = (0, 0)
    agents_edge: tuple[float, float] | None = None
    frames: dict[float, list[float]] = {}  # depth_t -> the true patrol depth from then
    cut: list[str] = []  # why the file ends early, if it does
    read = 0
    try:
        with open(path, "rb") as stream:
            for channel, message in _messages(stream, cut):
                read += 1
                topic = channel.topic
                if topic.startswith("/"):  # the Foxglove view (scene.build), derived
                    continue
                if topic.startswith("invalid/"):
                    invalid += 1
                    continue
                if topic.startswith("rejected/"):
                    rest = topic[len("rejected/"):]
                    rejected[rest] = rejected.get(rest, 0) + 1
                    continue
                found = parse_path(topic)
                if found is None:
                    if _LEGACY_TRUTH.match(topic):  # recordings before 2026-11-23: per robot
                        old = json.loads(message.data)
                        truth[int(old["robot"])].append(
                            (old["t"], old["x"], old["y"], old["theta"]))
                    continue
                kind, robot = found
                if kind.name == "alive":  # a liveliness token's news, no message type
                    if robot is not None:
                        alive[robot].append(
                            (message.log_time, bool(json.loads(message.data)["alive"])))
                    continue
                if kind.message not in _READ:
                    continue  # commands, scans: nothing the report measures
                try:
                    msg = from_record(kind.message, json.loads(message.data))
                except (DecodeError, ValueError):  # a record of another contract
                    invalid += 1
                    continue
                if isinstance(msg, Tick):
                    # the world's own wall clock when it has one, else the recorder's
                    ticks.append((msg.t, msg.wall_ns or message.log_time, message.log_time))
                    world_counts = (msg.dropped, msg.rejected)
                    live.append(sorted(msg.live))
                elif isinstance(msg, Fault):
                    faults.append({**dataclasses.asdict(msg), "log_ns": message.log_time})
                elif isinstance(msg, WireTruth):  # every robot's, one message per tick
                    for r, x, y, th in zip(msg.robots, msg.x, msg.y, msg.theta, strict=True):
                        truth[r].append((msg.t, x, y, th))
                elif isinstance(msg, AgentState):
                    states[msg.robot].append((msg.t, msg.lo, msg.hi, msg.phase, msg.phase_des,
                                              msg.workload, msg.depth_avg, msg.direction,
                                              msg.lower, msg.upper, msg.cycle_s))
                    agent_counts[msg.robot] = (msg.dropped, msg.rejected)
                    agents_edge = (msg.edge_lo, msg.edge_hi)
                elif isinstance(msg, Pose):
                    poses[msg.robot].append((msg.t, msg.x, msg.y, msg.theta))
                elif isinstance(msg, Sense):
                    odometry[msg.robot].append((msg.t, msg.odom_dist_m, msg.odom_dtheta))
                    if msg.pose:  # the pose the robot was given came with its sensing
                        poses[msg.robot].append((msg.t, *msg.pose))
                elif isinstance(msg, WorldInfo):
                    info = dataclasses.asdict(msg)
                    frames[msg.depth_t] = msg.patrol_depth
    except LoadError:
        raise
    except Exception as exc:  # the mcap reader raises many types on a damaged file
        raise LoadError(f"cannot read {path}: {type(exc).__name__}: {exc}") from None
    if cut and not read:
        raise LoadError(f"cannot read {path}: not one whole message: {cut[0]}")

    tick_t = np.asarray([tick[0] for tick in ticks], dtype=float)
    order = np.argsort(tick_t, kind="stable")
    tick_log = np.asarray([ticks[i][1] for i in order], dtype=np.int64)
    tick_recorded = np.asarray([ticks[i][2] for i in order], dtype=np.int64)
    return RunData(
        info=info,
        tick_t=tick_t[order],
        tick_log_ns=tick_log,
        tick_recorded_ns=tick_recorded,
        tick_live=[live[i] for i in order],
        faults=sorted(faults, key=lambda f: (f["t"], f["log_ns"])),
        truth={r: Truth(**_columns(rows, TRUTH_FIELDS)) for r, rows in truth.items()},
        states={r: States(**_one_of_each_time(_columns(rows, STATE_FIELDS)))
                for r, rows in states.items()},
        invalid=invalid,
        alive={r: sorted(ev) for r, ev in alive.items()},
        poses={r: Truth(**_columns(rows, TRUTH_FIELDS)) for r, rows in poses.items()},
        odometry={
            r: np.stack(list(_columns(rows, ODOM_FIELDS).values()))
            for r, rows in odometry.items()
        },
        agents_edge=agents_edge,
        cut_short=cut[0] if cut else "",
        rejected=rejected,
        depth_frames=sorted(frames.items()) if info.get("change_windows") else [],
        refused={"recorder_rejected": dict(sorted(rejected.items())),
                 "agents_dropped": {str(r): c[0] for r, c in sorted(agent_counts.items())},
                 "agents_rejected": {str(r): c[1] for r, c in sorted(agent_counts.items())},
                 "world_dropped": world_counts[0], "world_rejected": world_counts[1]},
    )

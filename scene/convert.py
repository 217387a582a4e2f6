"""Add the Foxglove channels to a finished recording, beside its raw ones.

The recorder writes each message as it comes (JSON, our own schemas) and decodes
nothing more than it must: it shares the two cores with the lockstep. This step runs
once the run is over (``btrack sim`` calls it before the report; ``btrack scene`` runs
it on any recording): it copies every raw record unchanged (channel, schema, log and
publish time, bytes) into a new file and adds, tick by tick, the scan as
``foxglove.LaserScan``, the true poses as ``foxglove.FrameTransforms`` and
``foxglove.PosesInFrame``, the estimated ones as ``foxglove.PosesInFrame``, the map and
the team as ``foxglove.SceneUpdate`` and the errors and segments as plottable JSON (see
``scene.build``), all protobuf from ``foxglove_schemas_protobuf``, zstd chunks, then
puts the new file in the old one's place. A channel of an earlier conversion is left
out and made anew, so running it twice gives the same file.

The Foxglove messages of tick k are stamped (log time and header) with the world's wall
clock of that tick (``Tick.wall_ns``), so they play as smoothly as the run went even
where the recorder, niced, took them late; a recording without ticks (hardware) stamps
them with the earliest log time of that tick's raw messages.
"""

from __future__ import annotations

import json
import os
from array import array
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from google.protobuf.descriptor import FileDescriptor
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from google.protobuf.message import Message
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from scene import build
from wire.codec import from_record
from wire.messages import AgentState, Particles, Scan, Truth, WorldInfo

PLOT_SCHEMAS = {
    build.ERRORS_TOPIC: {
        "title": "Errors",
        "description": "Phase and workload errors of each neighbour pair at tick k, as the "
                       "agents see them",
        "type": "object",
        "properties": {"t": {"type": "number"}, "k": {"type": "integer"},
                       "pairs": {"type": "array"},
                       "phase_rad": {"type": "array", "items": {"type": "number"}},
                       "workload_m2": {"type": "array", "items": {"type": "number"}},
                       "phase_abs_max_rad": {"type": "number"},
                       "workload_abs_max_m2": {"type": "number"}},
    },
    build.SEGMENTS_TOPIC: {
        "title": "Segments",
        "description": "Each robot's segment [lo, hi], workload, depth and phase at tick k, "
                       "by robot id (null: no state of that tick)",
        "type": "object",
        "properties": {name: {"type": "array"} for name in
                       ("lo", "hi", "workload", "depth_avg", "phase")},
    },
}


class ConvertError(Exception):
    """The recording cannot be given Foxglove channels (missing, not MCAP, unfinished)."""


def descriptor_set(cls: type[Message]) -> bytes:
    """The protobuf schema of ``cls`` as MCAP wants it: a FileDescriptorSet of its file
    and every file it imports."""
    files = FileDescriptorSet()
    seen: set[str] = set()

    def add(fd: FileDescriptor) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            add(dep)
        fd.CopyToProto(files.file.add())

    add(cls.DESCRIPTOR.file)
    return files.SerializeToString()


@dataclass
class Collected:
    """What the view needs of a run's raw messages, by tick."""

    info: WorldInfo | None = None
    ticks: dict[int, tuple[float, int]] = field(default_factory=dict)  # k -> t, wall ns
    first_log: dict[int, int] = field(default_factory=dict)  # k -> earliest log time
    truth: dict[int, Truth] = field(default_factory=dict)
    estimated: dict[int, dict[int, tuple[float, float, float]]] = field(
        default_factory=lambda: defaultdict(dict))
    states: dict[int, dict[int, AgentState]] = field(default_factory=lambda: defaultdict(dict))
    scans: dict[int, dict[int, Scan]] = field(default_factory=lambda: defaultdict(dict))
    clouds: dict[int, dict[int, Particles]] = field(default_factory=lambda: defaultdict(dict))
    times: dict[int, float] = field(default_factory=dict)  # k -> t

    def _seen(self, k: int, t: float, log_ns: int) -> None:
        self.times.setdefault(k, t)
        if log_ns < self.first_log.get(k, log_ns + 1):
            self.first_log[k] = log_ns

    def take(self, topic: str, data: bytes, log_ns: int) -> None:
        """One raw message of the recording (its JSON bytes)."""
        if topic == "laser/scan":
            msg = json.loads(data)
            msg["ranges"] = array("d", msg["ranges"])  # a third of a list's memory
            scan = from_record(Scan, msg)
            self.scans[scan.k][scan.scanner] = scan
            self._seen(scan.k, scan.t, log_ns)
            return
        parts = topic.split("/")
        if topic == "world/tick":
            msg = json.loads(data)
            self.ticks[msg["k"]] = (msg["t"], msg.get("wall_ns") or log_ns)
        elif topic == "world/truth":
            truth = from_record(Truth, json.loads(data))
            self.truth[truth.k] = truth
            self._seen(truth.k, truth.t, log_ns)
        elif topic == "world/info":
            self.info = from_record(WorldInfo, json.loads(data))
        elif len(parts) == 3 and parts[0] == "agent" and parts[2] == "state":
            state = from_record(AgentState, json.loads(data))
            self.states[state.k][state.robot] = state  # a state sent again replaces it
            self._seen(state.k, state.t, log_ns)
        elif len(parts) == 3 and parts[0] == "robot" and parts[2] == "particles":
            cloud = from_record(Particles, json.loads(data))
            self.clouds[cloud.k][cloud.robot] = cloud
            self._seen(cloud.k, cloud.t, log_ns)
        elif len(parts) == 3 and parts[0] == "robot" and parts[2] == "pose":
            msg = json.loads(data)
            self.estimated[msg["k"]][msg["robot"]] = (msg["x"], msg["y"], msg["theta"])
            self._seen(msg["k"], msg["t"], log_ns)
        elif len(parts) == 3 and parts[0] == "robot" and parts[2] == "sense":
            if b'"pose":[]' in data:  # no pose in it (a localizer's come apart): nothing
                return  # the view needs, and most of a pf run's messages
            msg = json.loads(data)
            if msg.get("pose"):  # truth or odometry poses travel in the Sense
                x, y, th = msg["pose"]
                self.estimated[msg["k"]][msg["robot"]] = (x, y, th)
            self._seen(msg["k"], msg["t"], log_ns)

    def stamp(self, k: int) -> int:
        tick = self.ticks.get(k)
        return tick[1] if tick is not None else self.first_log[k]

    def view(self) -> Iterator[tuple[str, int, Message | dict[str, Any]]]:
        """Every Foxglove message of the run, tick by tick: (topic, stamp ns, message)."""
        info = self.info
        shape = build.EdgeShape.of(info) if info is not None and info.patrol_depth else None
        radius = info.robot_radius if info is not None else 0.17
        ks = sorted(set(self.times) | set(self.ticks))
        if not ks:
            return
        if info is not None and info.patrol_depth:
            yield build.MAP_TOPIC, self.stamp(ks[0]), build.map_scene(info, self.stamp(ks[0]))
        ids: set[int] = set()
        for rows in (self.estimated, self.states):
            for row in rows.values():
                ids.update(row)
        for team in self.truth.values():
            ids.update(team.robots)
        robots = build.team_size(ids, info)
        bodies: set[int] = set()
        for k in ks:
            ns = self.stamp(k)
            t = self.ticks[k][0] if k in self.ticks else self.times[k]
            for scanner, scan in sorted(self.scans.get(k, {}).items()):
                yield build.scan_topic(scanner), ns, build.laser_scan(scan, ns)
            truth = self.truth.get(k)
            true_poses = build.truth_poses(truth) if truth is not None else {}
            if true_poses:
                yield build.TF_TOPIC, ns, build.frame_transforms(true_poses, ns)
                yield build.POSES_TRUE_TOPIC, ns, build.poses_in_frame(true_poses, ns)
            for robot, cloud in sorted(self.clouds.get(k, {}).items()):
                yield build.particles_topic(robot), ns, build.particle_cloud(cloud, ns)
            estimated = self.estimated.get(k, {})
            if estimated:
                yield build.POSES_ESTIMATED_TOPIC, ns, build.poses_in_frame(estimated, ns)
            drawn = true_poses or estimated  # the truth where there is one
            if drawn:
                if not true_poses:  # a run without truth (hardware): its frames
                    yield build.TF_TOPIC, ns, build.frame_transforms(estimated, ns)
                if not bodies.issuperset(drawn):  # every body in one message, for a seek
                    bodies.update(drawn)
                    yield build.ROBOTS_TOPIC, ns, build.robots_scene(bodies, radius, ns)
            states = self.states.get(k, {})
            if states:
                yield build.SEGMENTS_SCENE_TOPIC, ns, build.segments_scene(shape, states, t, k,
                                                                           ns)
            if states:
                yield build.ERRORS_TOPIC, ns, build.errors(states, t, k)
                yield build.SEGMENTS_TOPIC, ns, build.segments(states, robots, t, k)


def recording_path(path: str | Path) -> Path:
    """A run.mcap, or the run directory holding one."""
    path = Path(path)
    return path / "run.mcap" if path.is_dir() else path


def add_foxglove(path: str | Path) -> dict[str, int]:
    """Rewrite the recording at ``path`` with the Foxglove channels added; returns how
    many raw and view messages it holds. Raises ``ConvertError`` for a missing file, one
    that is not MCAP, or one its recorder did not finish (left as it is, so the report
    can still say what it lacks)."""
    path = recording_path(path)
    if not path.is_file():
        raise ConvertError(f"no recording at {path}")
    tmp = path.with_name(path.name + ".tmp")
    raw = view = 0
    try:
        with open(path, "rb") as src:
            reader = make_reader(src)
            try:
                header = reader.get_header()
                summary = reader.get_summary()
            except Exception as exc:  # the reader raises many types on what is not MCAP
                raise ConvertError(f"{path} is not a readable MCAP file "
                                   f"({type(exc).__name__}: {exc})") from None
            if summary is None:
                raise ConvertError(f"{path} has no summary (its recorder did not finish it); "
                                   "left as it is")
            collected = Collected()
            with open(tmp, "wb") as dst:
                writer = Writer(dst, compression=CompressionType.ZSTD)
                writer.start(profile=header.profile, library=header.library)
                schemas: dict[int, int] = {}
                channels: dict[int, int] = {}
                for schema, channel, message in reader.iter_messages(log_time_order=False):
                    if build.is_view_topic(channel.topic):
                        continue  # an earlier conversion's: made anew below
                    cid = channels.get(channel.id)
                    if cid is None:
                        sid = 0
                        if schema is not None:
                            sid = schemas.get(schema.id, 0)
                            if not sid:
                                sid = schemas[schema.id] = writer.register_schema(
                                    schema.name, schema.encoding, schema.data)
                        cid = channels[channel.id] = writer.register_channel(
                            channel.topic, channel.message_encoding, sid, channel.metadata)
                    writer.add_message(cid, message.log_time, message.data,
                                       message.publish_time, message.sequence)
                    raw += 1
                    collected.take(channel.topic, message.data, message.log_time)
                view = _write_view(writer, collected)
                writer.finish()
        os.replace(tmp, path)
    except ConvertError:
        tmp.unlink(missing_ok=True)
        raise
    except Exception as exc:
        tmp.unlink(missing_ok=True)
        raise ConvertError(f"cannot convert {path}: {type(exc).__name__}: {exc}") from None
    return {"raw_messages": raw, "view_messages": view}


def _write_view(writer: Writer, collected: Collected) -> int:
    channels: dict[str, int] = {}
    schemas: dict[str, int] = {}
    written = 0
    for topic, ns, msg in collected.view():
        cid = channels.get(topic)
        if cid is None:
            if isinstance(msg, dict):
                plot = PLOT_SCHEMAS[topic]
                sid = writer.register_schema(str(plot["title"]), "jsonschema",
                                             json.dumps(plot).encode())
                cid = writer.register_channel(topic, "json", sid, {"btrack": "view"})
            else:
                name = msg.DESCRIPTOR.full_name
                sid = schemas.get(name, 0)
                if not sid:
                    sid = schemas[name] = writer.register_schema(
                        name, "protobuf", descriptor_set(type(msg)))
                cid = writer.register_channel(topic, "protobuf", sid, {"btrack": "view"})
            channels[topic] = cid
        data = (json.dumps(msg, separators=(",", ":"), allow_nan=False).encode()
                if isinstance(msg, dict) else msg.SerializeToString())
        writer.add_message(cid, ns, data, ns)
        written += 1
    return written

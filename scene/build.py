"""The team as Foxglove draws it: wire messages in, Foxglove well-known messages out.

Pure: no file, no socket, no clock. Every function takes the run's own messages
(``wire.messages``) and a stamp (ns on the clock the viewer plays by) and returns the
protobuf classes of ``foxglove_schemas_protobuf``. One world frame, REP 103: x along
the edge, y up into the ice, z up out of the map; a robot's heading is a turn about z.
The recording's conversion (``scene.convert``) and a live view share this code.
"""

from __future__ import annotations

import bisect
import math
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import cached_property

from foxglove_schemas_protobuf.ArrowPrimitive_pb2 import ArrowPrimitive
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CylinderPrimitive_pb2 import CylinderPrimitive
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.TriangleListPrimitive_pb2 import TriangleListPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp

from agent.phase import wrap_pi
from wire.messages import AgentState, Particles, Scan, Truth, WorldInfo

WORLD = "world"  # the one fixed frame
ICE_ABOVE_M = 3.0  # ice drawn this far above the highest edge point (the maps' own margin)
WATER_BELOW_M = 2.5  # water drawn this far below the lowest edge point (robots and laser)
ROBOT_HEIGHT_M = 0.12  # a Create's height, for the cylinder

# Topics of the Foxglove channels. Every one starts with "/": no raw topic does (a key
# without its namespace), so a reader tells them apart by that alone (``is_view_topic``).
MAP_TOPIC = "/scene/map"
ROBOTS_TOPIC = "/scene/robots"
SEGMENTS_SCENE_TOPIC = "/scene/segments"
TF_TOPIC = "/tf"
POSES_TRUE_TOPIC = "/poses/true"
POSES_ESTIMATED_TOPIC = "/poses/estimated"
ERRORS_TOPIC = "/plot/errors"
SEGMENTS_TOPIC = "/plot/segments"


def particles_topic(robot: int) -> str:
    """Robot ``robot``'s particle cloud (a PointCloud in the world frame)."""
    return f"/particles/{robot}"


def particle_cloud(cloud: Particles, stamp_ns: int) -> PointCloud:
    """A sample of one robot's particles as a flat cloud in the world frame: x and y
    as 32-bit floats, z 0 (a millimetre is far above a float's resolution at 30 m)."""
    fields = [PackedElementField(name=n, offset=4 * j, type=PackedElementField.FLOAT32)
              for j, n in enumerate(("x", "y", "z"))]
    data = struct.pack(f"<{3 * len(cloud.x)}f",
                       *(v for x, y in zip(cloud.x, cloud.y, strict=True) for v in (x, y, 0.0)))
    return PointCloud(timestamp=stamp(stamp_ns), frame_id=WORLD, pose=pose(0.0, 0.0),
                      point_stride=12, fields=fields, data=data)


def scan_topic(scanner: int) -> str:
    return f"/scan/{scanner}"


def is_view_topic(topic: str) -> bool:
    """A channel of the Foxglove view (derived), not one of the run's own messages."""
    return topic.startswith("/")


def robot_frame(robot: int) -> str:
    return f"robot_{robot}"


# Robot colours: matplotlib's tab10, so the README's figures and Foxglove agree.
PALETTE = ((0.122, 0.467, 0.706), (1.0, 0.498, 0.055), (0.173, 0.627, 0.173),
           (0.839, 0.153, 0.157), (0.580, 0.404, 0.741), (0.549, 0.337, 0.294),
           (0.890, 0.467, 0.761), (0.498, 0.498, 0.498), (0.737, 0.741, 0.133),
           (0.090, 0.745, 0.812))
ICE = (0.93, 0.96, 1.0, 1.0)
ALGAE = (0.35, 0.70, 0.30, 1.0)
WATER = (0.20, 0.40, 0.75, 1.0)
EDGE = (0.05, 0.05, 0.05, 1.0)


def robot_colour(robot: int, alpha: float = 1.0) -> Color:
    r, g, b = PALETTE[robot % len(PALETTE)]
    return Color(r=r, g=g, b=b, a=alpha)


def stamp(ns: int) -> Timestamp:
    return Timestamp(seconds=ns // 1_000_000_000, nanos=ns % 1_000_000_000)


def yaw(theta: float) -> Quaternion:
    """A turn of ``theta`` about z."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * theta), w=math.cos(0.5 * theta))


def pose(x: float, y: float, theta: float = 0.0, z: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=yaw(theta))


def _rgba(c: tuple[float, float, float, float]) -> Color:
    return Color(r=c[0], g=c[1], b=c[2], a=c[3])


# the scan -----------------------------------------------------------------------
def laser_scan(scan: Scan, stamp_ns: int) -> LaserScan:
    """One scanner's sweep in the world frame: the scanner's pose is the scan's origin,
    the ranges exactly the message's; intensity 1 for a return, 0 for a beam that saw
    nothing (reads ``range_max``), so a viewer can hide the misses."""
    n = len(scan.ranges)
    msg = LaserScan(
        timestamp=stamp(stamp_ns), frame_id=WORLD,
        pose=pose(scan.scanner_x, scan.scanner_y, scan.scanner_theta),
        start_angle=scan.angle_min, end_angle=scan.angle_min + scan.angle_step * (n - 1))
    msg.ranges.extend(scan.ranges)
    top = scan.range_max
    msg.intensities.extend([0.0 if r >= top else 1.0 for r in scan.ranges])
    return msg


# poses --------------------------------------------------------------------------
Pose2 = tuple[float, float, float]  # x, y, theta


def truth_poses(truth: Truth) -> dict[int, Pose2]:
    return {r: (x, y, th) for r, x, y, th in zip(truth.robots, truth.x, truth.y, truth.theta,
                                                   strict=True)}


def poses_in_frame(poses: Mapping[int, Pose2], stamp_ns: int) -> PosesInFrame:
    """Every robot's pose, in the order of the robots' ids."""
    msg = PosesInFrame(timestamp=stamp(stamp_ns), frame_id=WORLD)
    for robot in sorted(poses):
        msg.poses.append(pose(*poses[robot]))
    return msg


def frame_transforms(poses: Mapping[int, Pose2], stamp_ns: int) -> FrameTransforms:
    """world -> robot_I for every robot: the frames a viewer can follow."""
    ts = stamp(stamp_ns)
    msg = FrameTransforms()
    for robot in sorted(poses):
        x, y, th = poses[robot]
        msg.transforms.append(FrameTransform(
            timestamp=ts, parent_frame_id=WORLD, child_frame_id=robot_frame(robot),
            translation=Vector3(x=x, y=y, z=0.0), rotation=yaw(th)))
    return msg


# the map ------------------------------------------------------------------------
@dataclass(frozen=True)
class EdgeShape:
    """The edge as WorldInfo gives it: bins of ``bin_m`` from ``lo``, each with the local
    edge's y and the true patrol depth."""

    lo: float
    hi: float
    bin_m: float
    edge_y: tuple[float, ...]
    patrol_depth: tuple[float, ...]
    min_depth: float

    @classmethod
    def of(cls, info: WorldInfo) -> EdgeShape:
        n = len(info.patrol_depth)
        edge_y = tuple(info.edge_y) if info.edge_y else (0.0,) * n
        return cls(info.edge_lo, info.edge_hi, info.bin_m, edge_y, tuple(info.patrol_depth),
                   info.min_depth)

    def y_at(self, x: float) -> float:
        if not self.edge_y:
            return 0.0
        b = min(max(int((x - self.lo) / self.bin_m), 0), len(self.edge_y) - 1)
        return self.edge_y[b]

    def runs(self) -> list[tuple[float, float, float, float]]:
        """Stretches (x0, x1, edge y, algae depth) over which both stay the same: the
        algae is drawn where it sets the patrol depth (deeper than ``min_depth``)."""
        out: list[tuple[float, float, float, float]] = []
        for b, (y, d) in enumerate(zip(self.edge_y, self.patrol_depth, strict=False)):
            x0 = self.lo + b * self.bin_m
            x1 = min(self.hi, x0 + self.bin_m)
            algae = d if d > self.min_depth + 1e-9 else 0.0
            if out and out[-1][2] == y and out[-1][3] == algae and abs(out[-1][1] - x0) < 1e-9:
                out[-1] = (out[-1][0], x1, y, algae)
            else:
                out.append((x0, x1, y, algae))
        return out

    @cached_property
    def _steps(self) -> tuple[float, ...]:
        """The x of every bin side where the local edge's y changes."""
        return tuple(self.lo + b * self.bin_m for b in range(1, len(self.edge_y))
                     if self.edge_y[b] != self.edge_y[b - 1])

    def line(self, x0: float, x1: float, above: float = 0.0, z: float = 0.0) -> list[Point3]:
        """Points along the local edge from x0 to x1, ``above`` it, at height z: a step
        where the edge's y changes, so a straight edge is two points."""
        steps = self._steps
        i, j = bisect.bisect_right(steps, x0), bisect.bisect_left(steps, x1)
        pts = [Point3(x=x0, y=self.y_at(x0) + above, z=z)]
        for x in steps[i:j]:
            pts.append(Point3(x=x, y=self.y_at(x - 1e-9) + above, z=z))
            pts.append(Point3(x=x, y=self.y_at(x + 1e-9) + above, z=z))
        pts.append(Point3(x=x1, y=self.y_at(x1 - 1e-9 if x1 > x0 else x1) + above, z=z))
        return pts


def _quad(tri: TriangleListPrimitive, x0: float, x1: float, y0: float, y1: float,
          z: float) -> None:
    p = [Point3(x=x0, y=y0, z=z), Point3(x=x1, y=y0, z=z), Point3(x=x1, y=y1, z=z),
         Point3(x=x0, y=y1, z=z)]
    tri.points.extend([p[0], p[1], p[2], p[0], p[2], p[3]])


def map_scene(info: WorldInfo, stamp_ns: int) -> SceneUpdate:
    """The scenario once: water, ice, the algae under it (where it sets the patrol
    depth), and the edge as a line."""
    shape = EdgeShape.of(info)
    runs = shape.runs()
    top = max(r[2] for r in runs) + ICE_ABOVE_M
    bottom = min(r[2] for r in runs) - WATER_BELOW_M
    water = TriangleListPrimitive(pose=pose(0, 0), color=_rgba(WATER))
    _quad(water, shape.lo - 1.0, shape.hi + 1.0, bottom, top, -0.002)
    ice = TriangleListPrimitive(pose=pose(0, 0), color=_rgba(ICE))
    algae = TriangleListPrimitive(pose=pose(0, 0), color=_rgba(ALGAE))
    for x0, x1, y, depth in runs:
        _quad(ice, x0, x1, y, top, -0.001)
        if depth > 0:
            _quad(algae, x0, x1, y, y + depth, 0.0)
    edge = LinePrimitive(type=LinePrimitive.LINE_STRIP, pose=pose(0, 0), thickness=0.02,
                         color=_rgba(EDGE), points=shape.line(shape.lo, shape.hi, z=0.001))
    entity = SceneEntity(
        timestamp=stamp(stamp_ns), frame_id=WORLD, id="map", frame_locked=True,
        triangles=[t for t in (water, ice, algae) if t.points], lines=[edge],
        metadata=[KeyValuePair(key="map", value=info.map),
                  KeyValuePair(key="edge", value=f"{info.edge_lo:g}..{info.edge_hi:g} m")])
    return SceneUpdate(entities=[entity])


# the team -----------------------------------------------------------------------
def robots_scene(robots: Iterable[int], radius_m: float, stamp_ns: int) -> SceneUpdate:
    """Every robot's body: a cylinder of its radius with its id and an arrow along its
    heading, in its own frame (``robot_I``, which ``frame_transforms`` moves), so the
    bodies are written once and follow the transforms."""
    ts = stamp(stamp_ns)
    update = SceneUpdate()
    for robot in sorted(robots):
        body = CylinderPrimitive(pose=pose(0.0, 0.0, 0.0, 0.5 * ROBOT_HEIGHT_M),
                                 size=Vector3(x=2 * radius_m, y=2 * radius_m, z=ROBOT_HEIGHT_M),
                                 bottom_scale=1.0, top_scale=1.0, color=robot_colour(robot))
        heading = ArrowPrimitive(pose=pose(0.0, 0.0, 0.0, ROBOT_HEIGHT_M + 0.01),
                                 shaft_length=0.8 * radius_m, shaft_diameter=0.03,
                                 head_length=0.1, head_diameter=0.08,
                                 color=Color(r=1.0, g=1.0, b=1.0, a=1.0))
        label = TextPrimitive(pose=pose(0.0, 0.0, 0.0, ROBOT_HEIGHT_M + 0.15), billboard=True,
                              font_size=14.0, scale_invariant=True, text=str(robot),
                              color=Color(r=0.0, g=0.0, b=0.0, a=1.0))
        update.entities.append(SceneEntity(
            timestamp=ts, frame_id=robot_frame(robot), id=f"robot/{robot}", frame_locked=True,
            cylinders=[body], arrows=[heading], texts=[label],
            metadata=[KeyValuePair(key="robot", value=str(robot)),
                      KeyValuePair(key="radius_m", value=repr(radius_m))]))
    return update


def segments_scene(shape: EdgeShape | None, states: Mapping[int, AgentState], t: float, k: int,
                   stamp_ns: int) -> SceneUpdate:
    """The team's segments at tick k, whole (it replaces the last update: an agent that
    left vanishes): each a stretch of the edge in its robot's colour, with the patrol
    depth its agent believes (``depth_avg``) drawn over it."""
    ts = stamp(stamp_ns)
    update = SceneUpdate(deletions=[SceneEntityDeletion(timestamp=ts,
                                                        type=SceneEntityDeletion.ALL)])
    meta = [KeyValuePair(key="t", value=repr(t)), KeyValuePair(key="k", value=str(k))]
    for robot in sorted(states):
        s = states[robot]
        line = shape.line if shape is not None else _straight
        stretch = LinePrimitive(type=LinePrimitive.LINE_STRIP, pose=pose(0, 0), thickness=0.06,
                                color=robot_colour(robot), points=line(s.lo, s.hi, 0.0, 0.01))
        depth = LinePrimitive(type=LinePrimitive.LINE_STRIP, pose=pose(0, 0), thickness=0.015,
                              color=robot_colour(robot, 0.8),
                              points=line(s.lo, s.hi, s.depth_avg, 0.01))
        y_lo, y_hi = _edge_y(shape, s.lo), _edge_y(shape, s.hi)
        ends = LinePrimitive(type=LinePrimitive.LINE_LIST, pose=pose(0, 0), thickness=0.01,
                             color=robot_colour(robot, 0.8),
                             points=[Point3(x=s.lo, y=y_lo, z=0.01),
                                     Point3(x=s.lo, y=y_lo + s.depth_avg, z=0.01),
                                     Point3(x=s.hi, y=y_hi, z=0.01),
                                     Point3(x=s.hi, y=y_hi + s.depth_avg, z=0.01)])
        update.entities.append(SceneEntity(
            timestamp=ts, frame_id=WORLD, id=f"segment/{robot}", frame_locked=True,
            lines=[stretch, depth, ends],
            metadata=[*meta, KeyValuePair(key="robot", value=str(robot)),
                      KeyValuePair(key="lo", value=repr(s.lo)),
                      KeyValuePair(key="hi", value=repr(s.hi)),
                      KeyValuePair(key="depth_avg", value=repr(s.depth_avg)),
                      KeyValuePair(key="workload", value=repr(s.workload))]))
    return update


def _edge_y(shape: EdgeShape | None, x: float) -> float:
    return shape.y_at(x) if shape is not None else 0.0


def _straight(x0: float, x1: float, above: float = 0.0, z: float = 0.0) -> list[Point3]:
    """A stretch of a straight edge at y = 0 (a run without its world's WorldInfo)."""
    return [Point3(x=x0, y=above, z=z), Point3(x=x1, y=above, z=z)]


# plottable numbers --------------------------------------------------------------
def errors(states: Mapping[int, AgentState], t: float, k: int) -> dict[str, object]:
    """The phase and workload errors of tick k as the agents see them (their published
    phases and workloads), e_phi,i = wrap(phi_{i+1} - phi_i) and e_Psi,i = Psi_{i+1} -
    Psi_i for each pair of consecutive robots with a state of that tick."""
    ids = sorted(states)
    pairs = list(zip(ids[:-1], ids[1:], strict=True))
    phase = [wrap_pi(states[b].phase - states[a].phase) for a, b in pairs]
    work = [states[b].workload - states[a].workload for a, b in pairs]
    return {"t": t, "k": k, "pairs": [[a, b] for a, b in pairs],
            "phase_rad": phase, "workload_m2": work,
            "phase_abs_max_rad": max((abs(e) for e in phase), default=0.0),
            "workload_abs_max_m2": max((abs(e) for e in work), default=0.0)}


def segments(states: Mapping[int, AgentState], robots: int, t: float,
             k: int) -> dict[str, object]:
    """Each robot's segment and workload at tick k, indexed by robot id (``hi[1]`` is
    robot 1's upper boundary), null for a robot with no state of that tick."""
    def col(name: str) -> list[float | None]:
        return [getattr(states[r], name) if r in states else None for r in range(robots)]

    return {"t": t, "k": k, "lo": col("lo"), "hi": col("hi"), "workload": col("workload"),
            "depth_avg": col("depth_avg"), "phase": col("phase")}


def team_size(ids: Iterable[int], info: WorldInfo | None) -> int:
    """How many robot slots the plots index: the world's team, or the highest id seen."""
    top = max(ids, default=-1) + 1
    return max(top, info.robots if info is not None else 0)


__all__ = ["ERRORS_TOPIC", "MAP_TOPIC", "POSES_ESTIMATED_TOPIC", "POSES_TRUE_TOPIC",
           "ROBOTS_TOPIC", "SEGMENTS_SCENE_TOPIC", "SEGMENTS_TOPIC", "TF_TOPIC", "EdgeShape",
           "errors", "frame_transforms", "is_view_topic", "laser_scan", "map_scene",
           "particle_cloud", "particles_topic", "poses_in_frame", "robot_frame",
           "robots_scene", "scan_topic", "segments",
           "segments_scene", "team_size", "truth_poses"]

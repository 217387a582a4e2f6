"""Draw a recording's scene from its Foxglove channels alone (no viewer app here):
the map's triangles and edge, each robot's segment and depth, the bodies where the
transforms put them, the estimated poses and the laser's returns, decoded with the
official protobuf classes, one tick of the run, seen from above."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader

from scene import build


@dataclass
class Frame:
    """The Foxglove messages of one tick (and the map and bodies in force then)."""

    t: float
    stamp_ns: int
    map: SceneUpdate | None = None
    robots: SceneUpdate | None = None
    segments: SceneUpdate | None = None
    transforms: FrameTransforms | None = None
    estimated: PosesInFrame | None = None
    scans: list[LaserScan] = field(default_factory=list)


def read_frame(path: str | Path, at_s: float) -> Frame:
    """The tick of the recording at ``path`` nearest ``at_s`` simulated seconds, as its
    Foxglove channels hold it."""
    import json

    with open(path, "rb") as stream:
        reader = make_reader(stream)
        best: tuple[float, float, int] | None = None
        for _, _, message in reader.iter_messages(topics=[build.SEGMENTS_TOPIC]):
            t = json.loads(message.data)["t"]
            if best is None or abs(t - at_s) < best[0]:
                best = (abs(t - at_s), t, message.log_time)
        if best is None:
            raise ValueError(f"{path} has no {build.SEGMENTS_TOPIC} channel: run btrack scene "
                             "on it first")
        frame = Frame(best[1], best[2])
        for _, channel, message in reader.iter_messages(end_time=frame.stamp_ns + 1):
            topic = channel.topic
            if not build.is_view_topic(topic):
                continue
            if topic == build.MAP_TOPIC:
                frame.map = SceneUpdate.FromString(message.data)
            elif topic == build.ROBOTS_TOPIC:
                frame.robots = SceneUpdate.FromString(message.data)
            elif message.log_time != frame.stamp_ns:
                continue
            elif topic == build.SEGMENTS_SCENE_TOPIC:
                frame.segments = SceneUpdate.FromString(message.data)
            elif topic == build.TF_TOPIC:
                frame.transforms = FrameTransforms.FromString(message.data)
            elif topic == build.POSES_ESTIMATED_TOPIC:
                frame.estimated = PosesInFrame.FromString(message.data)
            elif topic.startswith("/scan/"):
                frame.scans.append(LaserScan.FromString(message.data))
    return frame


def _rgba(c: object) -> tuple[float, float, float, float]:
    return (c.r, c.g, c.b, c.a)  # type: ignore[attr-defined]


def _yaw(q: object) -> float:
    import math

    return 2.0 * math.atan2(q.z, q.w)  # type: ignore[attr-defined]


def draw(frame: Frame, out: str | Path, title: str = "") -> Path:
    """The frame seen from above, as a PNG."""
    import math

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    fig, ax = plt.subplots(figsize=(10, 5.5), dpi=110)
    if frame.map is not None:
        for entity in frame.map.entities:
            for tri in entity.triangles:
                pts = [(p.x, p.y) for p in tri.points]
                for i in range(0, len(pts) - 2, 3):
                    ax.add_patch(Polygon(pts[i:i + 3], closed=True, lw=0, antialiased=False,
                                         fc=_rgba(tri.color), zorder=0))
            for line in entity.lines:
                ax.plot([p.x for p in line.points], [p.y for p in line.points],
                        color=_rgba(line.color), lw=1.2, zorder=1)
    for scan in frame.scans:
        ox, oy = scan.pose.position.x, scan.pose.position.y
        heading = _yaw(scan.pose.orientation)
        n = len(scan.ranges)
        step = (scan.end_angle - scan.start_angle) / (n - 1) if n > 1 else 0.0
        xs, ys = [], []
        for i, (r, hit) in enumerate(zip(scan.ranges, scan.intensities, strict=True)):
            if hit > 0:
                a = heading + scan.start_angle + i * step
                xs.append(ox + r * math.cos(a))
                ys.append(oy + r * math.sin(a))
        ax.plot([ox], [oy], marker="s", color="k", ms=6, zorder=5)
        ax.scatter(xs, ys, s=4, color="crimson", zorder=6, label="laser returns")
    if frame.segments is not None:
        for entity in frame.segments.entities:
            for j, line in enumerate(entity.lines):
                # the stretch of the edge, the believed depth over it, its two ends
                width, dash = ((5.0, "-"), (1.5, "--"), (1.0, "-"))[min(j, 2)]
                pts = [(p.x, p.y) for p in line.points]
                runs = ([pts[i:i + 2] for i in range(0, len(pts), 2)]
                        if line.type == line.LINE_LIST else [pts])
                for run in runs:
                    ax.plot([x for x, _ in run], [y for _, y in run], color=_rgba(line.color),
                            zorder=3, lw=width, ls=dash, alpha=0.9)
    frames = {}
    if frame.transforms is not None:
        frames = {tf.child_frame_id: tf for tf in frame.transforms.transforms}
    if frame.robots is not None:
        for entity in frame.robots.entities:
            tf = frames.get(entity.frame_id)
            if tf is None:
                continue
            x, y, th = tf.translation.x, tf.translation.y, _yaw(tf.rotation)
            for body in entity.cylinders:
                ax.add_patch(Circle((x, y), 0.5 * body.size.x, fc=_rgba(body.color),
                                    ec="k", lw=0.8, zorder=7))
                r = 0.5 * body.size.x
                ax.plot([x, x + r * math.cos(th)], [y, y + r * math.sin(th)], color="w",
                        lw=1.5, zorder=8)
            for text in entity.texts:
                ax.annotate(text.text, (x, y), xytext=(0, 14), textcoords="offset points",
                            ha="center", fontsize=9, zorder=9)
    if frame.estimated is not None:
        ax.scatter([p.position.x for p in frame.estimated.poses],
                   [p.position.y for p in frame.estimated.poses], marker="+", s=40,
                   color="k", zorder=10, label="estimated poses")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m), along the edge")
    ax.set_ylabel("y (m), into the ice")
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        unique = dict(zip(labels, handles, strict=True))
        ax.legend(unique.values(), unique.keys(), loc="upper right", fontsize=8)
    ax.set_title(title or f"t = {frame.t:.1f} s, from the recording's Foxglove channels")
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out)
    plt.close(fig)
    return out

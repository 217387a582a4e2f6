"""Issue 20: a run's recording with Foxglove's well-known channels beside the raw ones,
decoded with the official protobuf classes and checked against the raw messages of the
same tick; the scene drawn from those channels; and refusals of bad input."""

from __future__ import annotations

import json
import math
import shutil
import struct
import subprocess
import sys
from collections import Counter, defaultdict
from pathlib import Path

import pytest
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader

from report.load import load_run

OFFICIAL = {cls.DESCRIPTOR.full_name: cls
            for cls in (LaserScan, FrameTransforms, PosesInFrame, SceneUpdate, PointCloud)}


def _read(path: Path):
    """Raw messages by kind and tick, the view's decoded messages by topic, the
    schemas of the view's channels and the summary."""
    raw: dict[str, dict] = defaultdict(dict)
    view: dict[str, list] = defaultdict(list)
    schemas: dict[str, tuple[str, str, str]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            if topic.startswith("/"):
                schemas[topic] = (channel.message_encoding, schema.encoding, schema.name)
                if channel.message_encoding == "protobuf":
                    msg = OFFICIAL[schema.name].FromString(message.data)
                else:
                    msg = json.loads(message.data)
                view[topic].append((message.log_time, msg))
                continue
            if topic.startswith(("alive/", "invalid/", "rejected/")):
                continue
            msg = json.loads(message.data)
            if topic == "world/tick":
                raw["tick"][msg["k"]] = msg
            elif topic == "world/truth":
                raw["truth"][msg["k"]] = msg
            elif topic == "laser/scan":
                raw["scan"][msg["k"], msg["scanner"]] = msg
            elif topic.endswith("/pose"):
                raw["pose"][msg["k"], msg["robot"]] = msg
            elif topic.endswith("/particles"):
                raw["particles"][msg["k"], msg["robot"]] = msg
            elif topic.endswith("/state"):
                raw["state"][msg["k"], msg["robot"]] = msg
            elif topic == "world/info":
                raw["info"][0] = msg
    return raw, view, schemas, summary


def _yaw(q) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def test_every_foxglove_channel_decodes_and_matches_the_raw_messages(pf_run):
    raw, view, schemas, summary = _read(pf_run / "run.mcap")
    ticks = raw["tick"]
    assert len(ticks) == 200
    tick_of = {msg["wall_ns"]: k for k, msg in ticks.items()}
    assert len(tick_of) == len(ticks), "two ticks share a wall clock stamp"

    # every view channel is a Foxglove well-known schema in protobuf, or plottable JSON
    expected = {"/scan/0", "/scan/1", "/tf", "/poses/true", "/poses/estimated",
                "/scene/map", "/scene/robots", "/scene/segments", "/plot/errors",
                "/plot/segments", "/particles/0", "/particles/1"}
    assert set(view) == expected
    for topic, (encoding, schema_encoding, name) in schemas.items():
        if topic.startswith("/plot/"):
            assert (encoding, schema_encoding) == ("json", "jsonschema")
        else:
            assert (encoding, schema_encoding) == ("protobuf", "protobuf")
            assert name.startswith("foxglove.") and name in OFFICIAL

    # the scans: each scanner's on its own topic, ranges exactly the raw ones
    for scanner in (0, 1):
        scans = view[f"/scan/{scanner}"]
        assert len(scans) == 200
        for log_ns, scan in scans:
            k = tick_of[log_ns]
            src = raw["scan"][k, scanner]
            assert scan.timestamp.ToNanoseconds() == log_ns
            assert scan.frame_id == "world"
            assert list(scan.ranges) == src["ranges"]
            assert list(scan.intensities) == [0.0 if r >= src["range_max"] else 1.0
                                              for r in src["ranges"]]
            assert scan.start_angle == src["angle_min"]
            assert scan.end_angle == pytest.approx(
                src["angle_min"] + src["angle_step"] * (len(src["ranges"]) - 1))
            assert (scan.pose.position.x, scan.pose.position.y) == (src["scanner_x"],
                                                                  src["scanner_y"])
            assert _yaw(scan.pose.orientation) == pytest.approx(src["scanner_theta"])
    hits = sum(sum(scan.intensities) for _, scan in view["/scan/0"] + view["/scan/1"])
    assert hits > 200 * 2 * 3, "the scanners see the robots"

    # each robot's particle cloud (btrack sim --clouds-every 5): the raw sample's points
    for robot in (0, 1):
        clouds = view[f"/particles/{robot}"]
        assert len(clouds) == 40  # ticks 0, 5, ..., 195
        for log_ns, cloud in clouds:
            src = raw["particles"][tick_of[log_ns], robot]
            assert cloud.frame_id == "world" and cloud.point_stride == 12
            assert [f.name for f in cloud.fields] == ["x", "y", "z"]
            points = struct.unpack(f"<{len(cloud.data) // 4}f", cloud.data)
            assert len(src["x"]) == 200 and len(points) == 3 * 200
            assert points[0::3] == pytest.approx(src["x"], abs=1e-5)
            assert points[1::3] == pytest.approx(src["y"], abs=1e-5)
            pose = raw["pose"][tick_of[log_ns], robot]
            assert math.dist((sum(src["x"]) / 200, sum(src["y"]) / 200),
                             (pose["x"], pose["y"])) < 0.05  # the cloud is the robot's

    # robot i's true pose: world -> robot_i, and index i of the team's poses
    assert len(view["/tf"]) == len(view["/poses/true"]) == len(raw["truth"]) == 200
    for (log_ns, tfs), (_, poses) in zip(view["/tf"], view["/poses/true"], strict=True):
        truth = raw["truth"][tick_of[log_ns]]
        assert [tf.child_frame_id for tf in tfs.transforms] == ["robot_0", "robot_1"]
        for i, (tf, p) in enumerate(zip(tfs.transforms, poses.poses, strict=True)):
            assert tf.parent_frame_id == "world"
            assert (tf.translation.x, tf.translation.y) == (truth["x"][i], truth["y"][i])
            assert (p.position.x, p.position.y) == (truth["x"][i], truth["y"][i])
            assert _yaw(tf.rotation) == pytest.approx(math.remainder(truth["theta"][i],
                                                                     2 * math.pi), abs=1e-12)
    # and its estimate, the localizer's Pose of the same tick
    assert len(view["/poses/estimated"]) == 200
    for log_ns, poses in view["/poses/estimated"]:
        k = tick_of[log_ns]
        for i, p in enumerate(poses.poses):
            src = raw["pose"][k, i]
            assert (p.position.x, p.position.y) == (src["x"], src["y"])
            assert _yaw(p.orientation) == pytest.approx(
                math.remainder(src["theta"], 2 * math.pi), abs=1e-12)

    # the segments: a coloured stretch of the edge per agent, from lo to hi
    assert len(view["/scene/segments"]) == len({k for k, _ in raw["state"]})
    for log_ns, update in view["/scene/segments"]:
        k = tick_of[log_ns]
        assert [d.type for d in update.deletions] == [1]  # ALL: each update is whole
        for entity in update.entities:
            meta = {kv.key: kv.value for kv in entity.metadata}
            robot = int(meta["robot"])
            state = raw["state"][k, robot]
            assert int(meta["k"]) == k and entity.id == f"segment/{robot}"
            assert (float(meta["lo"]), float(meta["hi"])) == (state["lo"], state["hi"])
            stretch, depth = entity.lines[0].points, entity.lines[1].points
            assert (stretch[0].x, stretch[-1].x) == (state["lo"], state["hi"])
            assert depth[0].y - stretch[0].y == pytest.approx(state["depth_avg"])
    for log_ns, row in view["/plot/segments"]:
        k = tick_of[log_ns]
        for robot in (0, 1):
            state = raw["state"].get((k, robot))
            assert row["hi"][robot] == (state["hi"] if state else None)
    for log_ns, row in view["/plot/errors"]:
        k = tick_of[log_ns]
        s0, s1 = raw["state"][k, 0], raw["state"][k, 1]
        assert row["phase_rad"] == [pytest.approx(math.remainder(s1["phase"] - s0["phase"],
                                                                 2 * math.pi), abs=1e-12)]
        assert row["workload_m2"] == [s1["workload"] - s0["workload"]]

    # the map once, the robots' bodies in their own frames
    ((_, scene_map),) = view["/scene/map"]
    edge = scene_map.entities[0].lines[0].points
    info = raw["info"][0]
    assert (edge[0].x, edge[-1].x) == (info["edge_lo"], info["edge_hi"])
    assert len(scene_map.entities[0].triangles) == 3  # water, ice, algae (half-algae)
    ((_, bodies),) = view["/scene/robots"]
    assert [e.frame_id for e in bodies.entities] == ["robot_0", "robot_1"]
    assert [e.cylinders[0].size.x for e in bodies.entities] == [2 * info["robot_radius"]] * 2
    assert [e.texts[0].text for e in bodies.entities] == ["0", "1"]

    # chunks compressed; the raw channels all there, as many as the recorder wrote
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
    recorder = json.loads((pf_run / "logs" / "recorder.out").read_text().splitlines()[-1])
    counts = summary.statistics.channel_message_counts
    raw_count = sum(n for cid, n in counts.items()
                    if not summary.channels[cid].topic.startswith("/"))
    assert raw_count == recorder["messages"] + recorder["invalid"] + recorder["rejected"]
    assert load_run(pf_run / "run.mcap").tick_t.size == 200  # the report skips the view


def test_converting_again_changes_nothing(pf_run, tmp_path):
    """A second conversion makes the view anew and leaves every raw record as it was."""
    from scene.convert import add_foxglove

    copy = tmp_path / "run.mcap"
    shutil.copy(pf_run / "run.mcap", copy)
    add_foxglove(copy)

    def records(path):
        with open(path, "rb") as f:
            return [(c.topic, m.log_time, m.publish_time, m.data)
                    for _, c, m in make_reader(f).iter_messages(log_time_order=False)]

    before, after = records(pf_run / "run.mcap"), records(copy)
    assert Counter(r[0] for r in after) == Counter(r[0] for r in before)
    assert sorted(after) == sorted(before)


def btrack(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "btrack", *args], capture_output=True,
                          text=True, timeout=120)


def test_the_scene_drawn_from_the_foxglove_channels(pf_run, tmp_path):
    png = tmp_path / "scene.png"
    res = btrack("scene", str(pf_run), "--png", str(png), "--at", "15")
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_bad_recordings_are_refused_clearly(tmp_path):
    res = btrack("scene", str(tmp_path / "missing.mcap"))
    assert res.returncode == 2 and "no recording at" in res.stderr
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file" * 10)
    for args in ((str(junk),), (str(junk), "--png", str(tmp_path / "x.png"))):
        res = btrack("scene", *args)
        assert res.returncode == 2, res.stderr
        assert "Traceback" not in res.stderr and str(junk) in res.stderr
    assert junk.read_bytes() == b"this is not an mcap file" * 10  # left as it was
    assert not list(tmp_path.glob("*.tmp"))


def test_the_layout_names_the_recordings_channels(pf_run):
    """docs/foxglove-layout.json opens on such a recording: every topic its 3D panel
    shows and every path its plots draw is there."""
    layout = json.loads((Path(__file__).parent.parent / "docs" / "foxglove-layout.json")
                        .read_text())
    _, view, _, _ = _read(pf_run / "run.mcap")
    panels = layout["configById"]
    shown = set(panels["3D!btrack"]["topics"])
    assert shown - {"/scan/1"} <= set(view)  # a second scanner only on long edges
    for panel in ("Plot!errors", "Plot!segments"):
        for p in panels[panel]["paths"]:
            topic, rest = p["value"].split(".", 1)
            name, index = rest.rstrip("]").split("[")
            row = view[topic][-1][1]
            assert isinstance(row[name], list), p["value"]
            if topic == "/plot/segments":
                assert int(index) < 3
    assert set(_ids(layout["layout"])) == set(panels)


def _ids(node):
    if isinstance(node, str):
        yield node
    else:
        yield from _ids(node["first"])
        yield from _ids(node["second"])

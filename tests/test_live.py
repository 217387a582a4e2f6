"""Issue 20, item 2: ``btrack sim --live`` serves the team on the Foxglove WebSocket
protocol while it runs; a real client of that protocol (its own library,
@foxglove/ws-protocol, in node) connects, subscribes, and gets the scene and the scans."""

from __future__ import annotations

import base64
import json
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

from deploy.procs import listening
from tests.procutil import end, end_children_of_run, free_port

CLIENT = Path(__file__).parent / "foxglove_client"
# On the wall clock, so that the map and the bodies (sent again once a wall second)
# come five times however fast or loaded the machine: unpaced, two robots run 60 s
# in a second or two and a client that started late got only what was left.
DURATION_S = 15
TOPICS = ("/scene/map", "/scene/segments", "/scene/robots", "/scan/0", "/tf",
          "/poses/estimated", "/plot/errors", "/particles/0")


@pytest.fixture(scope="module")
def client_installed():
    if shutil.which("node") is None or shutil.which("npm") is None:
        pytest.skip("node and npm are needed for the Foxglove WebSocket client")
    if not (CLIENT / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        res = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--silent"],
                             cwd=CLIENT, capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-2000:]
    return CLIENT / "client.mjs"


def _counts(printed: str) -> object:
    """The client's messages per topic, for a failure's message (not its payloads)."""
    try:
        return {t: v["messages"] for t, v in json.loads(printed).items()}
    except (ValueError, KeyError, TypeError, AttributeError):
        return printed[-500:]


def test_a_foxglove_client_watches_the_team_as_it_runs(client_installed, tmp_path):
    out, port = tmp_path / "live", free_port()
    sim = subprocess.Popen(
        [sys.executable, "-m", "btrack", "sim", "--robots", "2", "--duration", str(DURATION_S),
         "--realtime", "--localization", "pf", "--clouds-every", "5", "--live", str(port),
         "--quiet", "--no-report", "--no-scene", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while not listening(port):
            assert sim.poll() is None, sim.communicate()[1][-2000:]
            assert time.monotonic() < deadline, "the live view never listened"
            time.sleep(0.1)
        client = subprocess.run(
            ["node", str(client_installed), f"ws://127.0.0.1:{port}", ",".join(TOPICS), "5",
             "60"], capture_output=True, text=True, timeout=90)
        watched_while_running = sim.poll() is None
        stdout, stderr = sim.communicate(timeout=240)
    finally:
        end(sim)
        end_children_of_run(out)
    assert client.returncode == 0, (_counts(client.stdout), client.stderr[-2000:])
    assert sim.returncode == 0, stderr[-2000:]
    assert watched_while_running, "the client got its messages only after the run"
    seen = json.loads(client.stdout)
    assert set(seen) == set(TOPICS)
    for topic in TOPICS:
        assert seen[topic]["messages"] >= 5, (topic, seen[topic]["messages"])
    assert seen["/scan/0"]["schemaName"] == "foxglove.LaserScan"
    scan = LaserScan.FromString(base64.b64decode(seen["/scan/0"]["first"]))
    assert scan.frame_id == "world" and len(scan.ranges) == 361 and sum(scan.intensities) > 0
    segments = SceneUpdate.FromString(base64.b64decode(seen["/scene/segments"]["first"]))
    assert {e.id for e in segments.entities} == {"segment/0", "segment/1"}
    scene_map = SceneUpdate.FromString(base64.b64decode(seen["/scene/map"]["first"]))
    assert scene_map.entities[0].id == "map" and scene_map.entities[0].triangles
    assert seen["/plot/errors"]["encoding"] == "json"
    cloud = PointCloud.FromString(base64.b64decode(seen["/particles/0"]["first"]))
    assert cloud.point_stride == 12 and len(cloud.data) == 12 * 200  # the localizer's sample
    view = json.loads((out / "logs" / "view.out").read_text().splitlines()[-1])
    assert view["frames"] > 10 and view["dropped"] == 0
    recorder = json.loads((out / "logs" / "recorder.out").read_text().splitlines()[-1])
    assert recorder["ticks"] == DURATION_S * 10 and recorder["done"]  # the run lost nothing to it


def test_view_refuses_what_it_cannot_join(tmp_path):
    for args in (["--run", str(tmp_path / "no-run")], ["--ns", "a b"], ["--port", "70000"]):
        res = subprocess.run([sys.executable, "-m", "btrack", "view", *args],
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 2, res.stderr
        assert res.stderr.startswith("btrack view: ") and "Traceback" not in res.stderr


def test_the_live_view_serves_each_robots_particles_once_per_scan():
    """The core of the live view, without a server: a robot's particle sample becomes
    its /particles/I cloud once, again only for a later scan, and a garbled sample is
    counted and dropped."""
    from scene.live import LiveView
    from wire.codec import encode
    from wire.messages import Particles

    view = LiveView()
    cloud = Particles(t=1.0, k=10, robot=1, x=[0.5, 0.75], y=[-1.0, 2.0])
    view.take("robot/1/particles", encode(cloud))
    drawn = dict(view.frame(1_000))
    points = struct.unpack("<6f", drawn["/particles/1"].data)
    assert points == (0.5, -1.0, 0.0, 0.75, 2.0, 0.0)
    assert "/particles/1" not in dict(view.frame(2_000))  # the same scan is not sent again
    view.take("robot/1/particles", encode(Particles(t=1.1, k=11, robot=1, x=[0.0], y=[0.0])))
    view.take("robot/2/particles", b"\x93garbage")
    drawn = dict(view.frame(3_000))
    assert len(drawn["/particles/1"].data) == 12 and "/particles/2" not in drawn
    assert view.dropped == 1

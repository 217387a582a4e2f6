"""The bridge processes, as real OS processes on a private Zenoh namespace, against
device emulators on pseudo-terminals: what they publish, what they do with commands,
the watchdog, faults and a port unplugged and plugged back."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from hwbridge.create import model as cm
from hwbridge.emulators.pty import CreateEmulator, Faults, LmsEmulator
from hwbridge.lms.codec import UNIT_CM, LmsConfig
from tests.procutil import end, free_port, hub_session, member_args, start, unique_ns, wait_for
from wire import Cmd, Keys, Scan, Sense, decode, encode


def _summary(proc: subprocess.Popen[bytes]) -> dict:
    out = proc.stdout.read().decode() if proc.stdout else ""
    return json.loads(out.strip().splitlines()[-1])


def test_create_bridge_process(tmp_path: Path) -> None:
    ns, port = unique_ns(), free_port()
    keys = Keys(ns)
    faults = Faults(garbage=0.05, corrupt=0.05, truncate=0.02, seed=7)
    emu = CreateEmulator(tmp_path / "create1", cm.MODELS["create"], faults).start()
    dev = emu.device
    senses: list[Sense] = []
    with hub_session(ns, port) as session:
        session.declare_subscriber(keys.sense(1),
                                   lambda s: senses.append(decode(Sense, s.payload.to_bytes())))
        pub = session.declare_publisher(keys.cmd(1))
        proc = start(["bridge", "create", "--port", emu.path, "--id", "1", "--edge", "0,6",
                      *member_args(ns, port)], log=tmp_path / "bridge.log")
        try:
            with emu.lock:
                dev.analog, dev.digital = 900, 1
            wait_for(lambda: any(s.ice and s.algae for s in senses), 20, "Sense with ice")
            s = senses[-1]
            assert s.robot == 1 and s.dt == 0.1 and (s.edge_lo, s.edge_hi) == (0.0, 6.0)
            ks = [x.k for x in senses]
            assert ks == sorted(ks)
            # commands drive the wheels; the robot drives in safe mode
            for k in range(3):
                pub.put(encode(Cmd(1.0, k, 1, 0.25, 0.0)))
            wait_for(lambda: dev.wheel_speeds() == (0.25, 0.25), 10, "wheels at 0.25 m/s")
            with emu.lock:
                dev.add_motion(0.25, 0.0)
            wait_for(lambda: sum(x.odom_dist_m for x in senses) > 0.2, 10, "odometry")
            # commands stop: the bridge's watchdog stops the robot
            wait_for(lambda: dev.wheel_speeds() == (0.0, 0.0), 10, "watchdog stop")
            # the port is unplugged and plugged back: the bridge lives on, Sense resumes
            emu.port.unplug()
            n = len(senses)
            emu.port.plug()
            wait_for(lambda: len(senses) > n + 5, 20, "Sense after replug")
            assert proc.poll() is None
            pub.put(encode(Cmd(2.0, 99, 1, 0.1, 0.0)))
            pub.put(b"\x93garbage")  # a malformed command is dropped, not fatal
            wait_for(lambda: dev.wheel_speeds() == (0.1, 0.1), 10, "driving after replug")
        finally:
            end(proc)
            emu.stop()
    summary = _summary(proc)
    assert proc.returncode == 0
    assert summary["serial_errors"] > 0 and summary["port_losses"] >= 1
    assert summary["watchdog_trips"] >= 1 and summary["dropped"] == 1
    assert "Traceback" not in (tmp_path / "bridge.log").read_text()


def test_create_bridge_warns_of_a_babbling_robot_and_recovers(tmp_path: Path) -> None:
    """A Create that sends only garbage from the start (issue 19, item 5): the bridge says
    so, rate-limited and counted, keeps trying, and publishes once the robot answers."""
    ns, port = unique_ns(), free_port()
    keys = Keys(ns)
    emu = CreateEmulator(tmp_path / "create0", cm.MODELS["create"])
    emu.device.babble = True
    emu.start()
    log = tmp_path / "bridge.log"
    senses: list[Sense] = []
    with hub_session(ns, port) as session:
        session.declare_subscriber(keys.sense(0),
                                   lambda s: senses.append(decode(Sense, s.payload.to_bytes())))
        proc = start(["bridge", "create", "--port", emu.path, "--id", "0",
                      *member_args(ns, port)], log=log)
        try:
            wait_for(lambda: "no valid sensor frame" in log.read_text(), 20, "the warning")
            assert not senses and proc.poll() is None
            with emu.lock:
                emu.device.babble = False  # the robot starts answering
            wait_for(lambda: len(senses) >= 3, 20, "Sense once the robot answers")
        finally:
            end(proc)
            emu.stop()
    summary = _summary(proc)
    assert proc.returncode == 0
    assert summary["no_stream_warnings"] >= 1 and summary["sense"] >= 3
    assert summary["start_bursts"] >= 2 and summary["skipped_bytes"] > 0
    assert "Traceback" not in log.read_text()


def test_lms_bridge_process(tmp_path: Path) -> None:
    """An LMS measuring in cm (80 m): a 30 m return is published, range_max is the
    sensor's."""
    ns, port = unique_ns(), free_port()
    keys = Keys(ns)
    ranges = [3.0] * 361
    ranges[180], ranges[90], ranges[270] = 1.5, 30.0, math.inf
    emu = LmsEmulator(tmp_path / "lms", lambda: ranges,
                      config=LmsConfig(UNIT_CM, 0x00)).start()
    scans: list[Scan] = []
    with hub_session(ns, port) as session:
        session.declare_subscriber(keys.scan(),
                                   lambda s: scans.append(decode(Scan, s.payload.to_bytes())))
        proc = start(["bridge", "lms", "--port", emu.path, "--baud", "500000",
                      "--pose", "3,-2,1.5707963", *member_args(ns, port)],
                     log=tmp_path / "lms.log")
        try:
            wait_for(lambda: len(scans) >= 5, 30, "five scans")
        finally:
            end(proc)
            emu.stop()
    s = scans[-1]
    assert len(s.ranges) == 361 and s.ranges[180] == 1.5 and s.ranges[0] == 3.0
    assert s.ranges[90] == 30.0 and s.ranges[270] == s.range_max == 81.83
    assert math.isclose(s.angle_min, -math.pi / 2) and math.isclose(s.angle_step,
                                                                      math.radians(0.5))
    assert (s.scanner_x, s.scanner_y) == (3.0, -2.0)
    summary = _summary(proc)
    assert summary["scans"] >= 5 and summary["baud"] == 500000


def test_bad_port_exits_with_a_message(tmp_path: Path) -> None:
    for args in (["bridge", "create", "--port", str(tmp_path / "none"), "--id", "0"],
                 ["bridge", "lms", "--port", str(tmp_path / "none")]):
        res = subprocess.run([sys.executable, "-m", "btrack", *args], capture_output=True,
                             timeout=60)
        assert res.returncode == 2
        assert b"cannot open" in res.stderr and b"Traceback" not in res.stderr

"""Drivers against the device emulators on real pseudo-terminals: start-up, stream,
commands, odometry, garbage, truncation, bad checksums, a port unplugged and plugged
back, the watchdog. Time given to the drivers' pure parts is passed explicitly."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from hwbridge.create import model as cm
from hwbridge.create_driver import CreateDriver
from hwbridge.emulators.pty import CreateEmulator, Faults, LmsEmulator
from hwbridge.lms_driver import LmsDriver
from hwbridge.transport import PortError, SerialTransport
from tests.hwdrive import pump
from tests.procutil import wait_for


@pytest.fixture
def create_emu(tmp_path: Path) -> Iterator[CreateEmulator]:
    emu = CreateEmulator(tmp_path / "create0", cm.MODELS["create"]).start()
    yield emu
    emu.stop()


def test_create_start_stream_command_odometry(create_emu: CreateEmulator) -> None:
    dev = create_emu.device
    drv = CreateDriver(create_emu.path, cm.MODELS["create"], ice=cm.IceSensor(512))
    drv.open()
    try:
        pump(drv, lambda: drv.reading is not None, 5, "a stream frame")
        assert dev.mode == "safe" and drv.reading and drv.reading.mode == "safe"
        drv.tick(time.monotonic())  # forget what came before
        with create_emu.lock:
            dev.analog, dev.digital = 800, 0b1
            dev.add_motion(0.1234, math.radians(10.0))
        frames0 = drv.parser.stats.frames
        pump(drv, lambda: drv.parser.stats.frames >= frames0 + 3, 5, "three more frames")
        s = drv.tick(time.monotonic())
        assert s is not None and s.ice and s.algae
        assert s.odom_dist_m == pytest.approx(0.123, abs=1e-9)  # whole mm; 0.4 mm kept
        assert s.odom_dtheta == pytest.approx(math.radians(10.0))
        now = time.monotonic()
        drv.command(0.2, 0.5, now)
        wait_for(lambda: dev.wheel_speeds() != (0.0, 0.0), 5, "wheels turning")
        right, left = dev.wheel_speeds()
        assert (right + left) / 2 == pytest.approx(0.2, abs=1e-3)
        assert (right - left) / cm.CREATE_WHEEL_BASE_M == pytest.approx(0.5, abs=0.01)
        # commands stop: the watchdog stops the wheels (time passed explicitly)
        drv.tick(now + 0.4)
        assert dev.wheel_speeds() != (0.0, 0.0)
        drv.tick(now + 0.6)
        wait_for(lambda: dev.wheel_speeds() == (0.0, 0.0), 5, "the watchdog's stop")
        assert drv.watchdog.trips == 1
        assert drv.serial_errors == 0
    finally:
        drv.close()


def test_create_survives_garbage_corruption_truncation(tmp_path: Path) -> None:
    faults = Faults(garbage=0.2, corrupt=0.2, truncate=0.1, seed=3)
    emu = CreateEmulator(tmp_path / "create", cm.MODELS["create"], faults).start()
    drv = CreateDriver(emu.path, cm.MODELS["create"])
    try:
        drv.open()
        with emu.lock:
            emu.device.add_motion(1.0, 0.0)  # a metre, reported over many frames
        pump(drv, lambda: drv.parser.stats.frames >= 60, 10, "60 good frames")
        assert faults.injected > 10
        assert drv.parser.stats.errors > 0  # counted...
        assert drv.serial_errors == drv.parser.stats.errors
        assert drv.reading is not None and drv.reading.mode == "safe"  # ...and survived
    finally:
        drv.close()
        emu.stop()


def test_create_port_unplugged_and_plugged_back(create_emu: CreateEmulator) -> None:
    dev = create_emu.device
    drv = CreateDriver(create_emu.path, cm.MODELS["create"])
    drv.open()
    try:
        drv.command(0.3, 0.0, time.monotonic())
        wait_for(lambda: dev.wheel_speeds() == (0.3, 0.3), 5, "driving")
        create_emu.port.unplug()
        pump(drv, lambda: not drv.connected, 5, "the loss to be seen")
        assert drv.transport.stats.losses == 1
        assert drv.tick(time.monotonic()) is None  # no sensing while the port is down
        create_emu.port.plug()
        pump(drv, lambda: drv.connected and drv.reading is not None
             and drv.parser.stats.frames > 0, 10, "reconnect")
        # on reopen the bridge restarted the robot with the wheels stopped
        wait_for(lambda: dev.mode == "safe" and dev.wheel_speeds() == (0.0, 0.0), 5,
                 "robot restarted and stopped")
        assert drv.transport.stats.opens == 2
    finally:
        drv.close()


def test_create2_encoders_wrap(tmp_path: Path) -> None:
    spec = cm.MODELS["create2"]
    emu = CreateEmulator(tmp_path / "c2", spec).start()
    drv = CreateDriver(emu.path, spec)
    try:
        drv.open()
        pump(drv, lambda: drv.parser.stats.frames >= 2, 5, "frames")
        drv.tick(time.monotonic())
        total = 0.0
        for _ in range(12):  # 12 x 0.9 m = 10.8 m: ~24,000 counts, past 65,535 with the start
            with emu.lock:
                emu.device.add_motion(0.9, 0.0)
            f0 = drv.parser.stats.frames
            pump(drv, lambda f0=f0: drv.parser.stats.frames >= f0 + 2, 5, "frames")
            s = drv.tick(time.monotonic())
            assert s is not None
            total += s.odom_dist_m
        with emu.lock:
            emu.device.add_motion(-3.0, 0.0)  # backwards across the wrap again
        f0 = drv.parser.stats.frames
        pump(drv, lambda: drv.parser.stats.frames >= f0 + 2, 5, "frames")
        s = drv.tick(time.monotonic())
        assert s is not None
        total += s.odom_dist_m
        assert total == pytest.approx(7.8, abs=0.002)  # within a count or two
    finally:
        drv.close()
        emu.stop()


def test_bad_port_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(PortError, match="cannot open"):
        SerialTransport(str(tmp_path / "nothing-here"), 57600).open()


def _lms(tmp_path: Path, faults: Faults | None = None) -> LmsEmulator:
    ranges = [2.0 + 0.001 * j for j in range(361)]
    return LmsEmulator(tmp_path / "lms", lambda: ranges, faults).start()


def test_lms_start_up_baud_change_variant_continuous(tmp_path: Path) -> None:
    emu = _lms(tmp_path)
    drv = LmsDriver(emu.path, baud=38400)
    try:
        drv.open()
        assert emu.device.baud == 38400 and drv.transport.baud == 38400
        assert emu.device.continuous and emu.device.geometry.beams == 361
        scans = pump(drv, lambda: drv.scans >= 3, 10, "three scans")
        assert len(scans[0]) == 361
        assert scans[0][0] == pytest.approx(2.0) and scans[0][360] == pytest.approx(2.36)
        assert drv.serial_errors == 0
    finally:
        drv.close()
        emu.stop()


def test_lms_resyncs_after_faults_and_replug(tmp_path: Path) -> None:
    faults = Faults(garbage=0.3, corrupt=0.3, truncate=0.2, seed=5)
    emu = _lms(tmp_path)
    drv = LmsDriver(emu.path, baud=500000)
    try:
        drv.open()  # start-up is clean; the damage starts now
        emu.faults = faults
        pump(drv, lambda: drv.scans >= 8, 20, "eight good scans among damaged ones")
        assert faults.injected > 0 and drv.serial_errors > 0
        emu.faults = Faults()
        emu.port.unplug()
        pump(drv, lambda: not drv.transport.is_open, 5, "the loss")
        emu.port.plug()
        n = drv.scans
        pump(drv, lambda: drv.scans >= n + 2, 15, "scans after the replug")
        assert drv.restarts >= 1 and emu.device.baud == 500000
    finally:
        drv.close()
        emu.stop()

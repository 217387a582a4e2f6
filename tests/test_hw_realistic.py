"""Drivers against emulators set to behave as the real devices do where the plain
emulators were kinder: a Create that is asleep, switched on late or rebooted, that
babbles, that truncates its odometry; an LMS that answers slowly, speaks its own units
and ranges, reports faults and partial scans. Byte level, on real pseudo-terminals;
each test here failed on the drivers before the fix it names."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from hwbridge.create import model as cm
from hwbridge.create_driver import CreateDriver
from hwbridge.emulators.devices import PowerPlan
from hwbridge.emulators.pty import CreateEmulator, LmsEmulator
from hwbridge.lms import codec as lms
from hwbridge.lms_driver import LmsDriver
from tests.hwdrive import pump
from tests.procutil import wait_for

# --- Create: the start burst is resent until the stream flows -----------------------


@pytest.mark.parametrize("plan", [PowerPlan(asleep_s=0.3), PowerPlan(boot_s=0.3)],
                         ids=["asleep", "switched-on-late"])
def test_create_streams_once_the_robot_can_hear(tmp_path: Path, plan: PowerPlan) -> None:
    spec = cm.MODELS["create"]
    emu = CreateEmulator(tmp_path / "create", spec, plan=plan).start()
    drv = CreateDriver(emu.path, spec)
    try:
        drv.open()
        pump(drv, lambda: drv.parser.stats.frames >= 3, 6, "the stream once the robot hears")
        assert emu.device.unheard_bytes > 0  # the first burst went unheard
        assert emu.device.mode == "safe"
        assert drv.tick(time.monotonic()) is not None
    finally:
        drv.close()
        emu.stop()


def test_create_restarted_after_a_reboot_mid_run(tmp_path: Path) -> None:
    spec = cm.MODELS["create"]
    emu = CreateEmulator(tmp_path / "create", spec, plan=PowerPlan(reboot_at_s=(0.6,))).start()
    dev = emu.device
    drv = CreateDriver(emu.path, spec)
    try:
        drv.open()
        pump(drv, lambda: drv.parser.stats.frames >= 3, 5, "the stream before the reboot")
        pump(drv, lambda: dev.reboots == 1, 5, "the reboot")
        frames = drv.parser.stats.frames
        pump(drv, lambda: drv.parser.stats.frames >= frames + 3, 6,
             "the stream after the reboot")
        assert dev.mode == "safe"
    finally:
        drv.close()
        emu.stop()


# --- Create: a clean shutdown leaves the robot out of Safe mode -----------------------


@pytest.mark.parametrize("model,tail,mode", [
    ("create2", bytes([145, 0, 0, 0, 0, 150, 0, 128, 173]), "off"),
    ("create", bytes([145, 0, 0, 0, 0, 150, 0, 128]), "passive"),
], ids=["create2", "create"])
def test_create_close_sends_the_robot_out_of_safe_mode(tmp_path: Path, model: str,
                                                        tail: bytes, mode: str) -> None:
    spec = cm.MODELS[model]
    emu = CreateEmulator(tmp_path / "create", spec).start()
    dev = emu.device
    drv = CreateDriver(emu.path, spec)
    try:
        drv.open()
        pump(drv, lambda: drv.parser.stats.frames >= 2, 5, "the stream")
        assert dev.mode == "safe"
        drv.close()
        wait_for(lambda: bytes(emu.received).endswith(tail), 5, "the closing bytes")
        with emu.lock:
            assert dev.mode == mode and not dev.streaming and dev.bad_commands == 0
    finally:
        drv.close()
        emu.stop()


# --- Create: odometry from packets the firmware truncates at every read ---------------


def test_create_odometry_of_a_slow_turn_survives_truncated_packets(tmp_path: Path) -> None:
    spec = cm.MODELS["create"]
    emu = CreateEmulator(tmp_path / "create", spec, drop_remainder=True, moves=True).start()
    dev = emu.device
    drv = CreateDriver(emu.path, spec, watchdog_s=30.0)
    try:
        drv.open()
        pump(drv, lambda: drv.parser.stats.frames >= 2, 5, "the stream")
        drv.tick(time.monotonic())
        with emu.lock:
            dist0, turned0 = dev.travelled_m, dev.turned_rad
        # 5 cm/s and 0.5 rad/s (29 deg/s): 0.75 mm and 0.43 degrees a frame, each read as 0
        drv.command(0.05, 0.5, time.monotonic())
        frames = drv.parser.stats.frames
        pump(drv, lambda: drv.parser.stats.frames >= frames + 40, 5, "40 frames of turning")
        drv.command(0.0, 0.0, time.monotonic())
        pump(drv, lambda: dev.wheel_speeds() == (0.0, 0.0), 5, "the wheels stopped")
        frames = drv.parser.stats.frames
        pump(drv, lambda: drv.parser.stats.frames >= frames + 3, 5, "frames at rest")
        s = drv.tick(time.monotonic())
        assert s is not None
        with emu.lock:
            dist, turned = dev.travelled_m - dist0, dev.turned_rad - turned0
        assert turned > 0.25 and dist > 0.025  # the robot did turn and move...
        assert s.odom_dtheta == pytest.approx(turned, abs=0.01)  # ...and odometry says so
        assert s.odom_dist_m == pytest.approx(dist, abs=0.002)
    finally:
        drv.close()
        emu.stop()


# --- LMS: replies as slow as a real sensor's ------------------------------------------

RANGES = [2.0 + 0.001 * j for j in range(361)]


def test_lms_start_up_waits_for_a_slow_reply(tmp_path: Path) -> None:
    """The sensor takes 1.6 s to stop its output, at 9600 baud after power-up, and the
    line carries only garbage between ends at different rates."""
    stop = lms.mode_change(lms.STOP_CONTINUOUS)[4:6]  # the telegram's payload
    emu = LmsEmulator(tmp_path / "lms", lambda: RANGES, reply_latency_s={stop: 1.6},
                      check_baud=True).start()
    drv = LmsDriver(emu.path, baud=38400)
    try:
        drv.open()
        assert emu.device.baud == drv.transport.baud == 38400
        scans = pump(drv, lambda: drv.scans >= 2, 10, "two scans")
        assert scans[0][0] == pytest.approx(2.0) and drv.serial_errors == 0
    finally:
        drv.close()
        emu.stop()


# --- LMS: decoding as the sensor's configuration says ---------------------------------

LONG_RANGES = [2.0] * 361
LONG_RANGES[10], LONG_RANGES[20], LONG_RANGES[30] = 12.0, 25.0, 30.0
LONG_RANGES[40], LONG_RANGES[50] = 60.0, math.inf


@pytest.mark.parametrize("config,range_max", [
    (lms.LmsConfig(lms.UNIT_MM, 0x00), 8.183),
    (lms.LmsConfig(lms.UNIT_MM, 0x04), 16.375),
    (lms.LmsConfig(lms.UNIT_MM, 0x06), 32.759),
    (lms.LmsConfig(lms.UNIT_MM, 0x0F), 32.759),
    (lms.LmsConfig(lms.UNIT_CM, 0x00), 81.83),
    (lms.LmsConfig(lms.UNIT_MM, 0x00, lms.REAL_TIME_INDICES), 8.183),
], ids=["mm-8m", "mm-16m", "mm-32m", "mm-32m-no-flags", "cm-80m",
       "mm-8m-real-time-indices"])
def test_lms_scans_read_as_the_sensor_is_configured(tmp_path: Path, config: lms.LmsConfig,
                                                    range_max: float) -> None:
    emu = LmsEmulator(tmp_path / "lms", lambda: LONG_RANGES, config=config).start()
    drv = LmsDriver(emu.path, baud=500000)
    try:
        drv.open()
        scans = pump(drv, lambda: drv.scans >= 2, 10, "two scans")
        want = [r if r < range_max else range_max for r in LONG_RANGES]
        assert scans[-1] == pytest.approx(want, abs=0.006)
        assert drv.range_max_m == range_max and drv.bad_scans == 0
    finally:
        drv.close()
        emu.stop()


# --- LMS: scans the sensor itself says are not to be used -----------------------------


@pytest.mark.parametrize("flag", ["fatal", "partial_scans"])
def test_lms_drops_and_counts_fatal_and_partial_scans(tmp_path: Path, flag: str) -> None:
    emu = LmsEmulator(tmp_path / "lms", lambda: RANGES).start()
    setattr(emu.device, flag, True)
    drv = LmsDriver(emu.path, baud=500000)
    try:
        drv.open()
        sent = emu.scans
        got = pump(drv, lambda: emu.scans >= sent + 5, 10, "five scans sent")
        pump(drv, lambda: drv.parser.stats.telegrams >= 5, 5, "them read")
        assert not got and drv.scans == 0  # none used...
        assert (drv.fatal_scans if flag == "fatal" else drv.partial_scans) > 0  # ...counted
        with emu.lock:
            setattr(emu.device, flag, False)  # whole, healthy scans again: used
        pump(drv, lambda: drv.scans >= 2, 10, "two good scans")
        assert drv.bad_scans == 0
    finally:
        drv.close()
        emu.stop()


def test_lms_start_up_resends_after_a_nak_at_the_right_rate(tmp_path: Path) -> None:
    """A NAK says the sensor heard us at this rate (the telegram was garbled on the way):
    resend there, do not go looking at another rate."""
    emu = LmsEmulator(tmp_path / "lms", lambda: RANGES, check_baud=True)
    emu.device.nak_next = 1
    emu.start()
    drv = LmsDriver(emu.path, baud=38400)
    try:
        drv.open()
        assert emu.device.naks == 1 and emu.device.baud == drv.transport.baud == 38400
    finally:
        drv.close()
        emu.stop()

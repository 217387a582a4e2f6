"""One iRobot Create on a serial port: transport + codec + model + watchdog, no bus.

``CreateDriver`` is what the bridge process calls: ``poll`` reads and parses what
arrived (reopening a lost port on its backoff) and sends the start burst (Start,
Safe/Full, zero wheels, the stream) whenever ``create.link.StartLink`` says so: at open,
again every 0.5 s until the stream flows (a robot asleep or switched on late does not hear
the first), then more slowly, and again when a stream that flowed stops (a reboot).
``command`` drives the wheels and feeds the watchdog, ``tick`` stops the wheels when
commands stopped and returns the sensing since the previous tick. The caller passes the
time (a monotonic clock in the process shell).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

from hwbridge.create import codec as oi
from hwbridge.create import link as ln
from hwbridge.create import model as cm
from hwbridge.transport import SerialTransport

log = logging.getLogger("btrack.bridge.create")


@dataclass(frozen=True)
class TickSensing:
    ice: bool
    algae: bool
    odom_dist_m: float
    odom_dtheta: float
    reading: cm.Reading
    frames: int  # stream frames since the previous tick


class CreateDriver:
    def __init__(self, port: str, spec: cm.ModelSpec, *, baud: int | None = None,
                 oi_mode: str = "safe", ice: cm.IceSensor | None = None, algae_bit: int = 0,
                 watchdog_s: float = 0.5, max_wheel_m_s: float = 0.5,
                 link: ln.LinkTiming | None = None) -> None:
        self.spec = spec
        self.transport = SerialTransport(port, baud or spec.baud)
        self.parser = oi.StreamParser(spec.stream_ids)
        self.odometry = cm.Odometry(spec)
        self.ice_sensor = ice or cm.IceSensor()
        self.algae_bit = algae_bit
        self.oi_mode = oi_mode
        self.watchdog = cm.Watchdog(watchdog_s)
        self.max_wheel = max_wheel_m_s
        self.reading: cm.Reading | None = None
        self.frames_since_tick = 0
        self.mode_recoveries = 0
        self.stopped_by_watchdog = False
        self.wheels = (0, 0)
        self.stale_s = 0.5  # no frame for this long: the robot is not sensing
        self.link = ln.StartLink(link)
        self._last_frame: float | None = None
        self._was_open = False
        self._bytes_since_frame = 0

    # connection ---------------------------------------------------------------
    def open(self, now: float | None = None) -> None:
        """Open now (raises transport.PortError) and start the robot."""
        self.transport.open()
        self._restart(time.monotonic() if now is None else now)

    def _restart(self, now: float) -> None:
        """The port is (re)opened: forget what came before, start the robot at once."""
        self._last_frame = None
        self.parser.reset()
        self.odometry.reset()
        self.wheels = (0, 0)
        self._bytes_since_frame = 0
        self._was_open = True
        self.link.restart(now)
        self._follow_link(now)

    def _start_burst(self) -> bytes:
        mode = oi.full() if self.oi_mode == "full" else oi.safe()
        return oi.start() + mode + oi.drive_direct(0, 0) + oi.stream(self.spec.stream_ids)

    def _follow_link(self, now: float) -> None:
        step = self.link.step(now)
        for report in step.reports:
            if report == ln.STREAM_LOST:
                log.warning("%s: the sensor stream stopped (the robot rebooted, slept or was "
                            "switched off?); starting it again", self.transport.port)
                self.odometry.reset()  # a rebooted Create 2 counts its encoders from 0
                self.wheels = (0, 0)
            elif report == ln.NO_STREAM:
                log.warning("%s: no valid sensor frame for %.1f s (%d bytes arrived meanwhile, "
                            "none of them a frame); sending Start again (%d bursts so far). Is "
                            "the robot switched on and awake, and at %d baud?",
                            self.transport.port, now - self.link.quiet_since,
                            self._bytes_since_frame, self.link.bursts, self.transport.baud)
            elif report == ln.GAVE_UP:
                t = self.link.timing
                log.error("%s: no sensor stream after %d start bursts over %.1f s (%d bytes "
                          "arrived, none of them a frame); still trying, every %g s. Is the "
                          "robot switched on and awake, and at %d baud?",
                          self.transport.port, t.tries, now - self.link.quiet_since,
                          self._bytes_since_frame, t.slow_retry_s, self.transport.baud)
        if step.send_burst:
            self.wheels = (0, 0)
            self.transport.write(self._start_burst())

    @property
    def connected(self) -> bool:
        return self.transport.is_open

    @property
    def serial_errors(self) -> int:
        return self.parser.stats.errors + self.transport.stats.losses

    def poll(self, now: float) -> None:
        """Read and parse what arrived (waits up to the transport's read timeout)."""
        if not self.transport.is_open:
            if self._was_open:
                log.warning("%s lost; the robot cannot be reached (reopening)",
                            self.transport.port)
                self._was_open = False
            if self.transport.reopen(now):
                self._restart(now)  # zero wheels before any command resumes
            return
        data = self.transport.read()
        self._bytes_since_frame += len(data)
        for values in self.parser.feed(data) if data else ():
            self.reading = cm.reading_from(values)
            self.odometry.update(values)
            self.frames_since_tick += 1
            self._last_frame = now
            self._bytes_since_frame = 0
            self.link.frame(now)
        if self.transport.is_open:
            self._follow_link(now)

    # commands -----------------------------------------------------------------
    def _drive(self, right: int, left: int) -> None:
        self.wheels = (right, left)
        self.transport.write(oi.drive_direct(right, left))

    def command(self, v: float, omega: float, now: float) -> None:
        self.watchdog.feed(now)
        self.stopped_by_watchdog = False
        self._drive(*cm.wheels_from_cmd(v, omega, self.spec.wheel_base_m, self.max_wheel))

    def tick(self, now: float) -> TickSensing | None:
        """Once per control period: the watchdog, mode recovery, and the sensing since the
        previous tick: the latest reading and the odometry since then, even if no frame
        completed during this tick (a late frame's motion goes into the next tick); None
        when no frame came for ``stale_s`` (the port is down or the robot silent)."""
        if self.watchdog.expired(now):
            if not self.stopped_by_watchdog and self.wheels != (0, 0):
                log.warning("no command for %.1f s: stopping the wheels",
                            self.watchdog.timeout_s)
            self.stopped_by_watchdog = True
            self._drive(0, 0)  # every tick while expired: a lost byte cannot keep it moving
        r = self.reading
        if r is not None and r.mode == "passive" and not r.wheel_drop and self.connected:
            # The OI falls back to passive after a wheel drop or on the charger.
            self.mode_recoveries += 1
            self.transport.write(oi.full() if self.oi_mode == "full" else oi.safe())
        frames, self.frames_since_tick = self.frames_since_tick, 0
        if (r is None or self._last_frame is None or now - self._last_frame > self.stale_s
                or not self.connected):
            return None
        dist, dtheta = self.odometry.take()
        ice = self.ice_sensor.ice(r.cargo_analog)
        algae = cm.algae_from_digital(r.cargo_digital, self.algae_bit)
        return TickSensing(ice, algae, dist, dtheta, r, frames)

    def close(self) -> None:
        """Stop the wheels and the stream, and leave the robot as it was found: Start puts it
        back in passive mode (out of Safe or Full, so its buttons work and it charges and
        sleeps), then Stop ends the OI on a Create 2 (off mode), as libcreate's
        Serial::disconnect does (src/serial.cpp). The original Create's OI has no Stop."""
        if self.transport.is_open:
            self.transport.write(oi.drive_direct(0, 0) + oi.pause_resume(False) + oi.start()
                                 + (oi.stop() if self.spec.oi_stop else b""))
        self.transport.close()

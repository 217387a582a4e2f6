"""When the Create driver (re)sends its start burst, as a declared state machine. Pure: no
I/O, no clock (the caller passes the time).

The burst (Start, Safe or Full, zero wheels, Stream) makes the robot stream. A robot that
is asleep, switched on after the bridge or rebooted with the cable in (it comes back in
off mode, not streaming) does not hear a burst sent once, so the burst is resent until
frames flow: every ``retry_s`` for ``tries`` bursts (libcreate does the same, 10 tries
500 ms apart: src/serial.cpp, Serial::startReading), then every ``slow_retry_s`` for as
long as it takes. A stream that stops for ``lost_s`` (a reboot, the robot asleep) starts
it all again. While no frame comes, a warning is due ``warn_after_s`` after the last frame
(or the start) and then every ``warn_every_s``, so a robot that is silent or sends only
garbage is never a silent bridge (issue 19, item 5).

States and transitions (``TRANSITIONS``):

    starting  --frame-->        streaming
    starting  --tries_spent-->  retrying     (the "gave_up" report: an error to log)
    retrying  --frame-->        streaming
    streaming --silent-->       starting     (the "stream_lost" report)
    any       --restart-->      starting     (the port was opened or reopened)
"""

from __future__ import annotations

from dataclasses import dataclass

STARTING, RETRYING, STREAMING = "starting", "retrying", "streaming"

TRANSITIONS: dict[tuple[str, str], str] = {
    (STARTING, "frame"): STREAMING,
    (STARTING, "tries_spent"): RETRYING,
    (RETRYING, "frame"): STREAMING,
    (STREAMING, "silent"): STARTING,
    (STARTING, "restart"): STARTING,
    (RETRYING, "restart"): STARTING,
    (STREAMING, "restart"): STARTING,
}

# What ``step`` reports for the caller to log.
GAVE_UP = "gave_up"  # the quick tries are spent; slower retries from now on
STREAM_LOST = "stream_lost"  # a stream that flowed has stopped
NO_STREAM = "no_stream"  # still no frame (rate-limited)


@dataclass(frozen=True)
class LinkTiming:
    retry_s: float = 0.5
    tries: int = 10
    slow_retry_s: float = 2.0
    lost_s: float = 1.0  # 66 frame periods of 15 ms: not a late frame but a stopped stream
    warn_after_s: float = 2.0
    warn_every_s: float = 10.0


@dataclass(frozen=True)
class Step:
    send_burst: bool
    reports: tuple[str, ...] = ()


class StartLink:
    def __init__(self, timing: LinkTiming | None = None) -> None:
        self.timing = timing or LinkTiming()
        self.state = STARTING
        self.bursts = 0  # start bursts sent, all told
        self.losses = 0  # STREAM_LOST reports
        self.warnings = 0  # NO_STREAM reports
        self.quiet_since = 0.0  # the last frame, or when the present start began
        self._tries = 0
        self._next_burst = 0.0
        self._next_warn = 0.0
        self._last_frame = 0.0

    # transitions -----------------------------------------------------------------
    def _go(self, event: str, now: float) -> None:
        self.state = TRANSITIONS[(self.state, event)]
        if self.state == STARTING:  # the state's own data, reset on entry
            self._tries = 0
            self._next_burst = now
            if event == "restart":
                self.quiet_since = now
            self._next_warn = self.quiet_since + self.timing.warn_after_s
        elif self.state == RETRYING:
            self._next_burst = now + self.timing.slow_retry_s

    def restart(self, now: float) -> None:
        """The port was opened or reopened: start the robot now."""
        self._go("restart", now)

    def frame(self, now: float) -> None:
        """A good stream frame arrived."""
        self._last_frame = self.quiet_since = now
        if self.state != STREAMING:
            self._go("frame", now)

    # guards ------------------------------------------------------------------------
    def _silent(self, now: float) -> bool:
        return now - self._last_frame > self.timing.lost_s

    def _tries_spent(self) -> bool:
        return self._tries >= self.timing.tries

    # the step -----------------------------------------------------------------------
    def step(self, now: float) -> Step:
        """What to do at ``now``: send the burst or not, and what to report."""
        reports: list[str] = []
        if self.state == STREAMING:
            if not self._silent(now):
                return Step(False)
            self._go("silent", now)
            self.losses += 1
            reports.append(STREAM_LOST)
        send = False
        if self.state == STARTING and now >= self._next_burst:
            if self._tries_spent():
                self._go("tries_spent", now)
                reports.append(GAVE_UP)
            else:
                send = True
                self._tries += 1
                self._next_burst = now + self.timing.retry_s
        elif self.state == RETRYING and now >= self._next_burst:
            send = True
            self._next_burst = now + self.timing.slow_retry_s
        if self.state != STREAMING and now >= self._next_warn:
            self.warnings += 1
            self._next_warn = now + self.timing.warn_every_s
            reports.append(NO_STREAM)
        if send:
            self.bursts += 1
        return Step(send, tuple(reports))

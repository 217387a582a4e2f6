"""The time stamps of a hardware run: wall-clock seconds since the run's epoch.

Robot computers share only the wall clock (NTP), so every process of a run stamps
``t = wall - epoch`` with the same ``--epoch``; the value advances on the monotonic
clock (taken once against the wall clock at start), so a clock step mid-run cannot make
time run backwards. Only process shells use this; cores get ``t`` and ``dt``.
"""

from __future__ import annotations

import time


class RunClock:
    def __init__(self, epoch: float | None = None) -> None:
        wall, mono = time.time(), time.monotonic()
        self.epoch = wall if epoch is None else epoch
        self._offset = (wall - self.epoch) - mono

    def t(self, mono: float | None = None) -> float:
        """Seconds since the epoch at monotonic time ``mono`` (now if None), never < 0."""
        m = time.monotonic() if mono is None else mono
        return max(0.0, m + self._offset)

"""Driving a device driver against an emulator in a test: poll until a condition holds."""

from __future__ import annotations

import time
from collections.abc import Callable

from hwbridge.create_driver import CreateDriver
from hwbridge.lms_driver import LmsDriver


def pump(driver: CreateDriver | LmsDriver, cond: Callable[[], bool], timeout: float,
         what: str) -> list:
    """Poll the driver until ``cond()``; returns what LmsDriver.poll produced."""
    got: list = []
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        out = driver.poll(time.monotonic())
        if out:
            got += out
    return got

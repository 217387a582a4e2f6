"""``btrack bridge``: real devices on the bus (and the emulated ones of ``btrack sim --hil``).

Subcommands: ``create`` (one per robot computer), ``lms`` (the base station's laser),
``hil-world`` (the simulator's physics behind emulated devices on pseudo-terminals).
"""

from __future__ import annotations

import sys

from btrack.cli import dispatch

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "create": ("hwbridge.create_bridge", "an iRobot Create / Create 2 on a serial port"),
    "lms": ("hwbridge.lms_bridge", "a SICK LMS 2xx on a serial port"),
    "hil-world": ("hwbridge.hil_world",
                  "simulated physics behind emulated Creates and LMS on pseudo-terminals"),
}


def main(argv: list[str] | None = None) -> int:
    return dispatch("btrack bridge", SUBCOMMANDS, sys.argv[1:] if argv is None else argv)

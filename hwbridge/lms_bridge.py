"""``btrack bridge lms``: a SICK LMS 2xx on the bus (the base station's laser).

Starts the sensor (baud change, 180 degree / 0.5 degree variant, its configuration read,
continuous output) and publishes every scan as a ``Scan`` on ``keys.scan()``, in metres,
with range_max the longest range the sensor's units and range mode can report (8.183 m
in mm at 8 m, 81.83 m in cm) and the scanner's pose from the command line (where it
stands in the edge's frame). A lost port is logged,
counted and reopened, and the sensor started again. On exit it prints its counters
(scans, scan rate, serial bytes per second, errors) as one JSON line.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time

from hwbridge.common import add_epoch_arg, on_stop, parse_floats
from hwbridge.lms.codec import UNIT_MM
from hwbridge.lms.model import ScanGeometry
from hwbridge.lms_driver import LmsDriver, LmsError
from hwbridge.runclock import RunClock, tick_holding
from hwbridge.transport import PortError
from wire import Keys, Scan, encode
from wire.session import (
    add_session_args,
    bounded_session,
    declare_publisher,
    options_from_args,
)

log = logging.getLogger("btrack.bridge.lms")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack bridge lms",
        description="A SICK LMS 2xx on the bus: continuous scans published as Scan messages.")
    p.add_argument("--port", required=True, help="serial device, e.g. /dev/ttyUSB1")
    p.add_argument("--baud", type=int, default=38400, choices=[9600, 19200, 38400, 500000],
                   help="rate to switch to after power-up's 9600 (38400: about 5 scans/s; "
                        "500000 needs RS-422)")
    p.add_argument("--angle", type=int, default=180, choices=[100, 180],
                   help="angular range, degrees (180)")
    p.add_argument("--resolution", type=float, default=0.5, choices=[0.25, 0.5, 1.0],
                   help="angular resolution, degrees (0.5)")
    p.add_argument("--pose", default=f"3,-2,{math.pi / 2!r}", metavar="X,Y,THETA",
                   help="scanner pose in the edge's frame, m and rad (default 3,-2,pi/2: "
                        "1 m behind the start line, centred on a 6 m edge, facing the ice)")
    p.add_argument("--dt", type=float, default=0.1,
                   help="control period, s (0.1): a scan's tick is the one whose period "
                        "holds its measurement time")
    add_epoch_arg(p)
    add_session_args(p)
    return p


# The LMS 2xx's mirror turns at 75 Hz; a 0.5 degree scan interlaces two turns at 1 degree
# (0.25 degree: four, 100 degrees only), and the telegram goes out once the scan is
# done (LMS 200/211/221/291 Telegram Listing; sicktoolbox's SickLMS2xx). So a scan's
# middle is half its turns before its telegram's first byte.
TURN_S = 1.0 / 75.0
TURNS = {100: 1, 50: 2, 25: 4}  # by resolution in hundredths of a degree
BITS_PER_BYTE = 10  # 8N1: a start and a stop bit


def measured_times(t_now: float, count: int, telegram_bytes: int, baud: int,
                   resolution_cdeg: int) -> list[float]:
    """When each of ``count`` scans read at ``t_now`` was measured (the middle of its
    sweep): the last one's telegram ended now, each earlier one a telegram's line time
    before the next."""
    line_s = BITS_PER_BYTE * telegram_bytes / baud
    middle_s = 0.5 * TURNS[resolution_cdeg] * TURN_S
    return [t_now - (count - j) * line_s - middle_s for j in range(count)]


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="btrack bridge lms: %(message)s")
    try:
        x, y, theta = parse_floats(args.pose, 3, "--pose")
        geometry = ScanGeometry(args.angle, int(round(args.resolution * 100)))
    except (argparse.ArgumentTypeError, ValueError) as exc:
        print(f"btrack bridge lms: {exc}", file=sys.stderr)
        return 2
    driver = LmsDriver(args.port, args.baud, geometry)
    try:
        driver.open()
    except (PortError, LmsError) as exc:
        print(f"btrack bridge lms: {exc}", file=sys.stderr)
        return 2
    clock = RunClock(args.epoch)
    keys = Keys(args.ns)
    stopping = False

    def stop() -> None:
        nonlocal stopping
        stopping = True

    began = time.monotonic()
    with bounded_session(options_from_args(args), "btrack bridge") as session:
        pub = declare_publisher(session, keys.scan())
        on_stop(stop)
        try:
            while not stopping:
                now = time.monotonic()
                scans = driver.poll(now)
                if not driver.transport.is_open:
                    time.sleep(0.01)  # port down: the reopen backoff paces the retries
                times = measured_times(clock.t(now), len(scans), driver.telegram_bytes,
                                       driver.transport.baud, geometry.resolution_centideg)
                for ranges, t in zip(scans, times, strict=True):
                    t = max(0.0, t)
                    pub.put(encode(Scan(
                        t=t, k=tick_holding(t, args.dt), ranges=ranges, scanner_x=x,
                        scanner_y=y, scanner_theta=theta, angle_min=geometry.angle_min,
                        angle_step=geometry.angle_step, range_max=driver.range_max_m)))
        finally:
            driver.close()
    wall = time.monotonic() - began
    ps, ts = driver.parser.stats, driver.transport.stats
    print(json.dumps({
        "bridge": "lms", "scans": driver.scans, "wall_s": round(wall, 3),
        "scan_rate_hz": round(driver.scans / wall, 2) if wall > 0 else None,
        "bytes_in": ts.bytes_in, "bytes_out": ts.bytes_out,
        "bytes_per_s": round((ts.bytes_in + ts.bytes_out) / wall, 1) if wall > 0 else None,
        "baud": driver.transport.baud, "serial_errors": driver.serial_errors,
        "bad_crc": ps.bad_crc, "bad_header": ps.bad_header, "naks": ps.naks,
        "bad_scans": driver.bad_scans, "fatal_scans": driver.fatal_scans,
        "partial_scans": driver.partial_scans, "port_losses": ts.losses,
        "restarts": driver.restarts,
        "units": "mm" if driver.config.units == UNIT_MM else "cm",
        "measuring_mode": driver.config.measuring_mode, "range_max": driver.range_max_m,
        "real_time_indices": driver.config.real_time_indices,
    }), flush=True)
    return 0

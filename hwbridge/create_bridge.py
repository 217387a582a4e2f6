"""``btrack bridge create``: one iRobot Create on the bus, as simworld publishes it.

Publishes ``Sense`` on ``keys.sense(I)`` at the control rate (10 Hz; k and t from the
run clock, so every robot of a run has the same k at the same time): ice from the
upward IR sensor on the cargo bay analog input, algae from a cargo bay digital input,
odometry since the previous tick. Takes ``Cmd`` from ``keys.cmd(I)`` and drives the
wheels at once (Drive Direct, wheel limits kept); the watchdog stops the wheels when
commands stop. A lost port is logged, counted, reopened on a backoff, and the robot
restarted with its wheels stopped; a robot that does not stream (asleep, switched on late,
rebooted) is sent the start burst again until it does, with a warning every 10 s while
it stays silent or sends only garbage. On exit it prints its counters as
one JSON line.
"""

from __future__ import annotations

import argparse
import json
import logging
import queue
import sys
import time

from hwbridge.common import add_epoch_arg, on_stop, parse_floats
from hwbridge.create import model as cm
from hwbridge.create_driver import CreateDriver
from hwbridge.runclock import RunClock, tick_of
from hwbridge.transport import PortError
from wire import Cmd, DecodeError, Keys, Sense, decode, encode
from wire.session import (
    add_session_args,
    bounded_session,
    declare_publisher,
    options_from_args,
)

log = logging.getLogger("btrack.bridge.create")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack bridge create",
        description="One iRobot Create (or Create 2) on the bus: publishes its Sense, "
        "drives it from its agent's Cmd, stops it when commands stop.")
    p.add_argument("--port", required=True, help="serial device, e.g. /dev/ttyUSB0")
    p.add_argument("--id", type=int, required=True, help="robot id (0-based)")
    p.add_argument("--model", choices=sorted(cm.MODELS), default="create",
                   help="create (57600 baud, odometry from packets 19/20) or create2 "
                        "(115200 baud, odometry from encoders 43/44); default create")
    p.add_argument("--baud", type=int, help="override the model's baud rate")
    p.add_argument("--oi-mode", choices=["safe", "full"], default="safe",
                   help="OI mode to drive in (safe: the robot stops itself on a wheel drop "
                        "or cliff; default safe)")
    p.add_argument("--ice-threshold", type=int, default=512,
                   help="cargo bay analog value (0..1023) at or above which the upward IR "
                        "sensor sees ice (calibrate; default 512)")
    p.add_argument("--ice-invert", action="store_true",
                   help="ice when the analog value is below the threshold instead")
    p.add_argument("--algae-input", type=int, default=0, choices=[0, 1, 2, 3],
                   help="cargo bay digital input of the algae sensor (default 0, pin 17)")
    p.add_argument("--edge", default="0,6", metavar="LO,HI",
                   help="the edge segment [s_0, s_n] in metres (default 0,6)")
    p.add_argument("--dt", type=float, default=0.1, help="control period, s (0.1)")
    p.add_argument("--watchdog", type=float, default=0.5,
                   help="stop the wheels after this many seconds without a command (0.5)")
    p.add_argument("--max-wheel", type=float, default=0.5, help="wheel speed limit, m/s (0.5)")
    add_epoch_arg(p)
    add_session_args(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING,
                        format=f"btrack bridge create {args.id}: %(message)s")
    try:
        edge_lo, edge_hi = parse_floats(args.edge, 2, "--edge")
    except argparse.ArgumentTypeError as exc:
        print(f"btrack bridge create: {exc}", file=sys.stderr)
        return 2
    if not edge_lo < edge_hi or args.id < 0 or not args.dt > 0 or not args.watchdog > 0:
        print("btrack bridge create: need LO < HI, --id >= 0, --dt > 0, --watchdog > 0",
              file=sys.stderr)
        return 2
    spec = cm.MODELS[args.model]
    if not spec.cargo_bay:
        log.warning("a Create 2 has no cargo bay inputs: ice and algae read as false")
    driver = CreateDriver(args.port, spec, baud=args.baud, oi_mode=args.oi_mode,
                          ice=cm.IceSensor(args.ice_threshold, args.ice_invert),
                          algae_bit=args.algae_input, watchdog_s=args.watchdog,
                          max_wheel_m_s=args.max_wheel)
    try:
        driver.open()
    except PortError as exc:
        print(f"btrack bridge create: {exc}", file=sys.stderr)
        return 2
    clock = RunClock(args.epoch)
    keys = Keys(args.ns)
    events: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
    stopping = False

    def stop() -> None:
        nonlocal stopping
        stopping = True
        events.put(None)

    counts = {"ticks": 0, "sense": 0, "missed_ticks": 0, "cmds": 0, "dropped": 0}
    began = time.monotonic()
    with bounded_session(options_from_args(args), "btrack bridge") as session:
        pub = declare_publisher(session, keys.sense(args.id))
        sub = session.declare_subscriber(keys.cmd(args.id),
                                         lambda s: events.put(s.payload.to_bytes()))
        on_stop(stop)
        k = tick_of(clock.t(), args.dt) + 1
        next_tick = clock.mono_at(k * args.dt)
        first_k = k
        try:
            while not stopping:
                now = time.monotonic()
                driver.poll(now)
                if not driver.connected:  # nothing to read: wait on commands instead
                    try:
                        item = events.get(timeout=0.01)
                        events.put(item) if item is not None else None
                    except queue.Empty:
                        pass
                while True:
                    try:
                        payload = events.get_nowait()
                    except queue.Empty:
                        break
                    if payload is None:
                        continue
                    try:
                        cmd = decode(Cmd, payload)
                        if cmd.robot != args.id:
                            raise DecodeError(f"command for robot {cmd.robot}")
                    except DecodeError as exc:
                        counts["dropped"] += 1
                        if counts["dropped"] <= 10:
                            log.warning("dropped a command: %s", exc)
                        continue
                    counts["cmds"] += 1
                    driver.command(cmd.v, cmd.omega, time.monotonic())
                now = time.monotonic()
                if now >= next_tick:
                    sensing = driver.tick(now)
                    if sensing is None:
                        counts["missed_ticks"] += 1
                    else:
                        pub.put(encode(Sense(
                            clock.t(now), k, args.id, sensing.ice, sensing.algae,
                            sensing.odom_dist_m, sensing.odom_dtheta, edge_lo, edge_hi,
                            args.dt)))
                        counts["sense"] += 1
                    # the next tick on the epoch's grid (after a stall, ticks are skipped)
                    k = max(k + 1, tick_of(clock.t(now), args.dt) + 1)
                    counts["ticks"] = k - first_k
                    next_tick = clock.mono_at(k * args.dt)
        finally:
            driver.close()
            sub.undeclare()
    wall = time.monotonic() - began
    ps, ts = driver.parser.stats, driver.transport.stats
    print(json.dumps({
        "bridge": "create", "robot": args.id, "model": args.model,
        "serial_errors": driver.serial_errors, "bad_checksum": ps.bad_checksum,
        "bad_length": ps.bad_length, "skipped_bytes": ps.skipped_bytes, "frames": ps.frames,
        "port_losses": ts.losses, "opens": ts.opens, "bytes_in": ts.bytes_in,
        "bytes_out": ts.bytes_out, "wall_s": round(wall, 3),
        "bytes_per_s": round((ts.bytes_in + ts.bytes_out) / wall, 1) if wall > 0 else None,
        "watchdog_trips": driver.watchdog.trips, "mode_recoveries": driver.mode_recoveries,
        "start_bursts": driver.link.bursts, "stream_losses": driver.link.losses,
        "no_stream_warnings": driver.link.warnings,
        **counts}), flush=True)
    return 0

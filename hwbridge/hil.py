"""``btrack sim --hil``: the whole hardware stack on this machine, with no hardware.

Processes, each its own OS process on a fresh namespace over loopback: the recorder,
``btrack bridge hil-world`` (the simulator's physics behind emulated Creates and an
emulated LMS on pseudo-terminals), one ``btrack bridge create`` per robot and one
``btrack bridge lms`` (the real bridges, opening the pseudo-terminals as they would
open /dev/ttyUSB*), and the agents. Hardware time is the wall clock, so the run lasts
``--duration`` wall seconds. At the end: the report from the recording, and
``summary.json`` gains ``"hil": true`` and ``serial_errors`` (what each bridge counted
and survived), plus the bridges' serial throughput and the scan rate.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import zenoh

from deploy.procs import (
    AGENT_FLAGS,
    Child,
    ProcessGroup,
    forward_flags,
    free_port,
    stop_interrupted,
)
from simworld.maps import MapError, load_map
from wire import Keys
from wire.session import SessionOptions, open_session

DEFAULT_FAULTS = 0.005  # one device message in 200 damaged on purpose
# On the wall clock an agent must not wait for a late neighbour longer than the bridge's
# watchdog (0.5 s) lets its robot run without a command.
NEIGHBOUR_TIMEOUT_S = 0.3


def _fail(group: ProcessGroup, child: Child, what: str) -> int:
    print(f"\nbtrack sim --hil: {child.name} {what} (exit code {child.proc.returncode}); "
          f"its log {child.log_path}:\n{child.log_tail()}", file=sys.stderr)
    group.stop_all()
    return 1


def hil_stats(out: Path, n: int) -> dict[str, Any]:
    """What the HIL run adds to summary.json, from its processes' last JSON lines (also
    written, with every counter, to OUT/hil.json)."""

    def last(name: str) -> dict[str, Any]:
        try:
            lines = (out / "logs" / f"{name}.out").read_text().strip().splitlines()
            return json.loads(lines[-1]) if lines else {}
        except (OSError, json.JSONDecodeError):
            return {}

    world_stats = last("hil-world")
    bridge_stats = {name: last(name) for name in [f"bridge{i}" for i in range(n)]
                    + ["bridge-lms"]}
    serial_errors = {name: st.get("serial_errors") for name, st in bridge_stats.items()}
    hil = {
        "hil": True,
        "serial_errors": serial_errors,
        "serial_errors_total": sum(v or 0 for v in serial_errors.values()),
        "faults_injected": world_stats.get("faults_injected"),
        "port_losses": sum(st.get("port_losses", 0) for st in bridge_stats.values()),
        "scan_rate_hz": bridge_stats["bridge-lms"].get("scan_rate_hz"),
        "lms_bytes_per_s": bridge_stats["bridge-lms"].get("bytes_per_s"),
        "create_bytes_per_s": [bridge_stats[f"bridge{i}"].get("bytes_per_s")
                               for i in range(n)],
    }
    (out / "hil.json").write_text(json.dumps({**hil, "world": world_stats,
                                              "bridges": bridge_stats}, indent=1))
    return hil


def _wait_paths(paths: list[Path], child: Child, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not all(p.exists() for p in paths):
        if not child.alive() or time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def run(args: argparse.Namespace) -> int:
    """Run a HIL team from ``btrack sim``'s arguments (plus ``hil_faults``)."""
    try:
        gmap = load_map(args.map, args.scale, args.seed)
        gmap.check_room()
    except MapError as exc:
        print(f"btrack sim --hil: {exc}", file=sys.stderr)
        return 2
    faults = getattr(args, "hil_faults", None)
    faults = DEFAULT_FAULTS if faults is None else faults
    out: Path = args.out or Path("runs") / time.strftime("hil-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    devices = out / "dev"
    ns = args.ns or f"btrack/hil-{os.getpid()}-{int(time.time() * 1000) % 10**9}"
    keys = Keys(ns)
    port = args.port if getattr(args, "port", None) is not None else free_port()
    hub = SessionOptions(ns=ns, mode="peer", listen=(f"tcp/127.0.0.1:{port}",), multicast=False)
    member = SessionOptions(ns=ns, mode="peer", connect=(f"tcp/127.0.0.1:{port}",),
                            listen=("tcp/127.0.0.1:0",), multicast=False).to_args()
    epoch = ["--epoch", repr(time.time())]
    group = ProcessGroup(out / "logs")
    n = args.robots
    print(f"btrack sim --hil: {n} emulated Creates and an emulated LMS behind the real "
          f"bridges, map {args.map}, start {args.start}, {args.duration:g} s wall -> {out}")
    began = time.monotonic()
    recorder_alive = False
    try:
        with open_session(hub) as session:

            def on_recorder(sample: zenoh.Sample) -> None:
                nonlocal recorder_alive
                recorder_alive = sample.kind == zenoh.SampleKind.PUT

            _sub = session.liveliness().declare_subscriber(keys.alive_recorder(), on_recorder,
                                                           history=True)
            recorder = group.start("recorder", ["record", "--out", str(out), *member])
            while not recorder_alive:
                if not recorder.alive() or time.monotonic() - began > 60:
                    return _fail(group, recorder, "did not come up")
                time.sleep(0.1)
            world = group.start("hil-world", [
                "bridge", "hil-world", "--dir", str(devices), "--robots", str(n),
                "--map", args.map, "--scale", str(args.scale), "--start", args.start,
                "--seed", str(args.seed), "--duration", str(args.duration),
                "--faults", str(faults), "--wait-recorder", *epoch, *member])
            paths = [devices / f"create{i}" for i in range(n)] + [devices / "lms"]
            if not _wait_paths(paths, world, 60):
                return _fail(group, world, "did not create its devices")
            edge = f"{gmap.edge_lo!r},{gmap.edge_hi!r}"
            bridges = [group.start(f"bridge{i}", [
                "bridge", "create", "--port", str(devices / f"create{i}"), "--id", str(i),
                "--model", "create", "--edge", edge, *epoch, *member]) for i in range(n)]
            lms = group.start("bridge-lms", ["bridge", "lms", "--port", str(devices / "lms"),
                                             "--baud", "38400", *epoch, *member])
            agents = [group.start(f"agent{i}", [
                "agent", "--id", str(i), "--robots", str(n), "--neighbour-timeout",
                str(NEIGHBOUR_TIMEOUT_S), *forward_flags(args, AGENT_FLAGS), *member])
                for i in range(n)]
            last_print = time.monotonic()
            while world.alive() and not world.last_json():
                try:
                    world.proc.wait(0.5)
                except Exception:
                    pass
                for child in (*bridges, lms, *agents, recorder):
                    # the recorder ends by itself, cleanly, once it has the done Tick
                    if not child.alive() and not (child is recorder
                                                  and child.proc.returncode == 0):
                        return _fail(group, child, "exited early")
                if not args.quiet and time.monotonic() - last_print >= 10:
                    last_print = time.monotonic()
                    print(f"  {last_print - began:6.0f} s wall", flush=True)
            if not world.alive() and world.proc.returncode != 0:
                return _fail(group, world, "failed")
            try:
                recorder.proc.wait(20)
            except Exception:
                pass
            for child in (*agents, *bridges, lms):  # before the devices go away
                group.stop(child)
            group.stop_all()
    except KeyboardInterrupt as exc:
        return stop_interrupted(group, exc, "btrack sim --hil")
    finally:
        group.stop_all()
    wall = time.monotonic() - began
    hil = hil_stats(out, n)
    print(f"\nbtrack sim --hil: run finished in {wall:.1f} s wall; recording {out / 'run.mcap'}")
    from deploy.launcher import report_and_scene

    report_and_scene(out, args.no_report, args.no_scene, "btrack sim --hil", extra=hil)
    return 0

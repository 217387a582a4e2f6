"""``btrack sim --hil``: the whole hardware stack on this machine, with no hardware.

Processes, each its own OS process on a fresh namespace over loopback: the recorder,
``btrack bridge hil-world`` (the simulator's physics behind emulated Creates and an
emulated LMS on pseudo-terminals), one ``btrack bridge create`` per robot and one
``btrack bridge lms`` (the real bridges, opening the pseudo-terminals as they would
open /dev/ttyUSB*), the localizer on the LMS bridge's scans (``--timing measured``:
each scan at its measurement time, as a real LMS sends them, about 5 a second at
38400 baud; with ``--localization truth`` the world sends the true poses instead and no
localizer runs), and the agents. Hardware time is the wall clock, so the run lasts
``--duration`` wall seconds. At the end: the report from the recording, and
``summary.json`` gains ``"hil": true`` and ``serial_errors`` (what each bridge counted
and survived), plus the bridges' serial throughput and the scan rate.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from dataclasses import dataclass
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
from hwbridge.hil_world import laser_pose
from simworld.maps import MapError, load_map
from simworld.world import World
from wire import Keys
from wire.session import SessionOptions, open_session

DEFAULT_FAULTS = 0.005  # one device message in 200 damaged on purpose
# On the wall clock an agent must not wait for a late neighbour longer than the bridge's
# watchdog (0.5 s) lets its robot run without a command.
NEIGHBOUR_TIMEOUT_S = 0.3


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


PROGRESS_EVERY_S = 10.0  # wall seconds between the hardware loop's progress lines


@dataclass(frozen=True)
class HilPlan:
    """Everything the hardware loop takes from ``btrack sim``'s options: ``run`` reads
    this and never the options, so an option that changes no field here changes
    nothing (tests/test_sim_refusals.py holds every option to that)."""

    out: Path
    ns: str
    port: int
    robots: int
    edge: tuple[float, float]  # the map's edge, for the Create bridges
    commands: dict[str, list[str]]  # each process's btrack command line, by name
    quiet: bool
    progress_every_s: float
    report: bool
    scene: bool

    @property
    def devices(self) -> Path:
        return self.out / "dev"


def plan(args: argparse.Namespace, epoch: float) -> HilPlan:
    """The hardware loop's processes for ``btrack sim --hil`` options that the launcher
    has checked (``launcher.hil_refusal``): the recorder, the HIL world, a bridge per
    Create and one for the LMS, and the agents, on the run's ``epoch`` (Unix s).
    Raises MapError for a map the robots have no room on."""
    port = free_port() if args.port is None else args.port
    gmap = load_map(args.map, args.scale, args.seed)
    gmap.check_room()
    faults = DEFAULT_FAULTS if args.hil_faults is None else args.hil_faults
    out: Path = args.out
    devices = out / "dev"
    ns = args.ns or f"btrack/hil-{os.getpid()}-{int(time.time() * 1000) % 10**9}"
    member = SessionOptions(ns=ns, mode="peer", connect=(f"tcp/127.0.0.1:{port}",),
                            listen=("tcp/127.0.0.1:0",), multicast=False).to_args()
    on_epoch = ["--epoch", repr(epoch)]
    n = args.robots
    edge = f"{gmap.edge_lo!r},{gmap.edge_hi!r}"
    localization = args.localization or "pf"
    lx, ly, lth = laser_pose(World(gmap, n, args.start, args.seed))
    commands: dict[str, list[str]] = {
        "recorder": ["record", "--out", str(out), *member],
        "hil-world": [
            "bridge", "hil-world", "--dir", str(devices), "--robots", str(n),
            "--map", args.map, "--scale", str(args.scale), "--start", args.start,
            "--seed", str(args.seed), "--duration", str(args.duration),
            "--faults", str(faults), "--wait-recorder", "--localization", localization,
            *on_epoch, *member],
        **{f"bridge{i}": [
            "bridge", "create", "--port", str(devices / f"create{i}"), "--id", str(i),
            "--model", "create", "--edge", edge, *on_epoch, *member] for i in range(n)},
        "bridge-lms": ["bridge", "lms", "--port", str(devices / "lms"), "--baud", "38400",
                       "--pose", f"{lx!r},{ly!r},{lth!r}", *on_epoch, *member],
        # the filter on the LMS's scans at their measured times (localizer.timeline)
        **({"localizer": ["localizer", "--robots", str(n), "--timing", "measured",
                          "--seed", str(args.seed), *member]} if localization == "pf" else {}),
        **{f"agent{i}": [
            "agent", "--id", str(i), "--robots", str(n), "--neighbour-timeout",
            str(NEIGHBOUR_TIMEOUT_S), *forward_flags(args, AGENT_FLAGS), *member]
           for i in range(n)},
    }
    every = PROGRESS_EVERY_S if args.progress_every is None else args.progress_every
    return HilPlan(out=out, ns=ns, port=port, robots=n, edge=(gmap.edge_lo, gmap.edge_hi),
                   commands=commands, quiet=args.quiet, progress_every_s=every,
                   report=not args.no_report, scene=not args.no_scene)


def run(args: argparse.Namespace) -> int:
    """Run a HIL team from ``btrack sim``'s checked arguments (``args.out`` made)."""
    try:
        p = plan(args, time.time())
    except MapError as exc:
        print(f"btrack sim --hil: {exc}", file=sys.stderr)
        return 2
    return run_plan(p, args.map, args.start, args.duration)


def run_plan(p: HilPlan, map_name: str, start: str, duration: float) -> int:
    from deploy.launcher import fail, report_and_scene

    name = "btrack sim --hil"
    keys = Keys(p.ns)
    hub = SessionOptions(ns=p.ns, mode="peer", listen=(f"tcp/127.0.0.1:{p.port}",),
                         multicast=False)
    group = ProcessGroup(p.out / "logs")
    n = p.robots
    print(f"{name}: {n} emulated Creates and an emulated LMS behind the real "
          f"bridges, map {map_name}, start {start}, {duration:g} s wall -> {p.out}")
    began = time.monotonic()
    recorder_up = threading.Event()
    try:
        with open_session(hub) as session:

            def on_recorder(sample: zenoh.Sample) -> None:
                if sample.kind == zenoh.SampleKind.PUT:
                    recorder_up.set()
                else:
                    recorder_up.clear()

            _sub = session.liveliness().declare_subscriber(keys.alive_recorder(), on_recorder,
                                                           history=True)
            recorder = group.start("recorder", p.commands["recorder"])
            while not recorder_up.wait(0.1):
                if not recorder.alive() or time.monotonic() - began > 60:
                    return fail(group, recorder, "did not come up", name)
            world = group.start("hil-world", p.commands["hil-world"])
            paths = [p.devices / f"create{i}" for i in range(n)] + [p.devices / "lms"]
            if not _wait_paths(paths, world, 60):
                return fail(group, world, "did not create its devices", name)
            bridges = [group.start(f"bridge{i}", p.commands[f"bridge{i}"]) for i in range(n)]
            lms = group.start("bridge-lms", p.commands["bridge-lms"])
            helpers = [lms]
            if "localizer" in p.commands:
                helpers.append(group.start("localizer", p.commands["localizer"]))
            agents = [group.start(f"agent{i}", p.commands[f"agent{i}"]) for i in range(n)]
            last_print = time.monotonic()
            while world.alive() and not world.last_json():
                try:
                    world.proc.wait(0.5)
                except Exception:
                    pass
                for child in (*bridges, *helpers, *agents, recorder):
                    # the recorder ends by itself, cleanly, once it has the done Tick
                    if not child.alive() and not (child is recorder
                                                  and child.proc.returncode == 0):
                        return fail(group, child, "exited early", name)
                if not p.quiet and time.monotonic() - last_print >= p.progress_every_s:
                    last_print = time.monotonic()
                    print(f"  {last_print - began:6.0f} s wall", flush=True)
            if not world.alive() and world.proc.returncode != 0:
                return fail(group, world, "failed", name)
            try:
                recorder.proc.wait(20)
            except Exception:
                pass
            for child in (*agents, *bridges, *helpers):  # before the devices go away
                group.stop(child)
            group.stop_all()
    except KeyboardInterrupt as exc:
        return stop_interrupted(group, exc, name)
    finally:
        group.stop_all()
    wall = time.monotonic() - began
    hil = hil_stats(p.out, n)
    print(f"\n{name}: run finished in {wall:.1f} s wall; recording {p.out / 'run.mcap'}")
    report_and_scene(p.out, not p.report, not p.scene, name, extra=hil)
    return 0

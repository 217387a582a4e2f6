"""``btrack suite thesis``: the thesis's twelve simulated cases (tables 7.1, 7.2), each
a full multi-process ``btrack sim`` run, several at once; then the two tables with
the thesis's value beside ours in every cell, ``summary.json`` and ``report.md``.

Every case is its own launcher process (in its own process group) that starts and
ends its own world, recorder and agents; the suite ends the launchers it started on
finish, on error and on Ctrl-C (each launcher then ends its children).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from deploy.procs import ODOM_FLAGS, forward_flags, interrupted_code, non_negative, stop_on_sigterm
from report.thesis import MAPS, STARTS, all_cases
from simworld.change import CHANGE_HELP, ChangeError, parse_changes

DEFAULT_DURATION_S = 1200.0


@dataclass
class Case:
    map: str
    start: str
    out: Path
    proc: subprocess.Popen[bytes] | None = None
    began: float = 0.0
    wall_s: float = 0.0
    code: int | None = None

    @property
    def name(self) -> str:
        return f"{self.map}_{self.start.replace(':', '')}"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack suite",
        description="Run the thesis's twelve simulated cases (three maps x four starts, "
        "tables 7.1 and 7.2), each a full multi-process team, and write the tables with "
        "the thesis's value beside ours.",
    )
    p.add_argument("name", choices=["thesis", "general"],
                   help="the suite to run: thesis, or general (random maps and team sizes; "
                   "btrack suite general --help)")
    p.add_argument("--out", type=Path, help="output directory (default runs/suite-<time>)")
    p.add_argument("--localization", default=None,
                   help="pose source for every case, as for btrack sim (default: btrack "
                   "sim's own default)")
    p.add_argument("--duration", type=float, default=DEFAULT_DURATION_S,
                   help=f"simulated seconds per case (default {DEFAULT_DURATION_S:g}: "
                   "steady state is the last quarter)")
    p.add_argument("--seed", type=int, default=1, help="map and noise seed (default 1)")
    p.add_argument("--jobs", type=int, default=default_jobs(),
                   help=f"cases run at once (default {default_jobs()} on this machine: "
                   "one per two cores, as a 3-robot team keeps about two cores busy)")
    p.add_argument("--maps", nargs="+", choices=MAPS, default=list(MAPS),
                   help="only these maps (default: all three)")
    p.add_argument("--starts", nargs="+", choices=STARTS, default=list(STARTS),
                   help="only these starts (default: all four)")
    p.add_argument("--config", metavar="FILE.toml", help="agent configuration for every case")
    p.add_argument("--odom-noise", type=non_negative, metavar="F",
                   help="wheel odometry noise for every case, as for btrack sim")
    p.add_argument("--odom-turn-noise", type=non_negative, metavar="F",
                   help="odometry turn noise for every case, as for btrack sim")
    p.add_argument("--sensors", choices=["ideal", "lab"],
                   help="sensor profile for every case, as for btrack sim (default ideal)")
    p.add_argument("--engine", choices=("bus", "inprocess"), default="bus",
                   help="bus: each case a full btrack sim team of processes; inprocess: each "
                   "in one process, the same cores bit for bit, in seconds (truth or "
                   "odometry poses) [bus]")
    p.add_argument("--change", action="append", default=[], metavar="SPEC",
                   help="every case's map changes during the run, as btrack sim --change "
                   "(repeatable): " + CHANGE_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def default_jobs() -> int:
    return max(1, (os.cpu_count() or 2) // 2)


def _sim_args(args: argparse.Namespace, case: Case) -> list[str]:
    out = [sys.executable, "-m", "btrack", "sim", "--robots", "3", "--map", case.map,
           "--start", case.start, "--duration", repr(args.duration), "--seed",
           str(args.seed), "--out", str(case.out), "--quiet",
           "--no-scene"]  # measures only; btrack scene CASE_DIR adds the Foxglove view
    if args.localization:
        out += ["--localization", args.localization]
    if args.config:
        out += ["--config", args.config]
    if args.sensors:
        out += ["--sensors", args.sensors]
    for spec in args.change:
        out += ["--change", spec]
    return out + forward_flags(args, ODOM_FLAGS)


def _start(case: Case, argv: list[str]) -> None:
    case.out.mkdir(parents=True, exist_ok=True)
    with open(case.out / "sim.log", "wb") as log:
        case.proc = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=log,
            stderr=subprocess.STDOUT, start_new_session=True,
        )
    case.began = time.monotonic()


def _stop(case: Case, grace_s: float = 30.0) -> None:
    """Interrupt a case's launcher (it ends its own children), then kill it."""
    proc = case.proc
    if proc is None or proc.poll() is not None:
        return
    try:
        os.kill(proc.pid, signal.SIGINT)
        proc.wait(grace_s)
    except subprocess.TimeoutExpired:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        pass


def _case_summary(case: Case) -> dict[str, Any]:
    from report.thesis import PHASE_SSE_RAD, WORKLOAD_SSE_M2, thesis_cell

    path = case.out / "summary.json"
    summary: dict[str, Any] = {"map": case.map, "start": case.start}
    if case.code == 0 and path.exists():
        summary = json.loads(path.read_text())
    else:
        summary["error"] = f"btrack sim exited with {case.code}; see {case.out / 'sim.log'}"
    summary["thesis_phase_sse_rad"] = thesis_cell(PHASE_SSE_RAD, case.map, case.start)
    summary["thesis_workload_sse_m2"] = thesis_cell(WORKLOAD_SSE_M2, case.map, case.start)
    summary["wall_s"] = round(case.wall_s, 1)
    summary["dir"] = case.out.name
    return summary


def _progress(case: Case, done: int, total: int, summary: dict[str, Any]) -> str:
    head = f"[{done}/{total}] {case.map:<12} {case.start:<8} {case.wall_s:6.1f} s wall"
    if "error" in summary:
        return f"{head}  FAILED: {summary['error']}"
    def num(key: str, spec: str) -> str:
        value = summary.get(key)  # a case that measured nothing (no last quarter) has None
        return format(value, spec) if isinstance(value, (int, float)) else "n/a"

    return (f"{head}  phase {num('phase_sse_rad', '.4f')} rad (thesis "
            f"{num('thesis_phase_sse_rad', '.3f')})  workload {num('workload_sse_m2', '.4f')}"
            f" m^2 (thesis {num('thesis_workload_sse_m2', '.3f')})")


def run_launchers(cases: list[Case], argv: Callable[[Case], list[str]], jobs: int,
                  finished: Callable[[Case], None]) -> None:
    """Start each case's launcher (``argv(case)``, its output in OUT/sim.log), ``jobs`` at
    once, and hand each to ``finished`` as it ends, its exit code and wall time set; on
    the way out, however it comes, interrupt those still running."""
    waiting, running = list(cases), list[Case]()
    try:
        while waiting or running:
            while waiting and len(running) < max(1, jobs):
                case = waiting.pop(0)
                _start(case, argv(case))
                running.append(case)
            time.sleep(0.2)
            for case in [c for c in running if c.proc is not None and c.proc.poll() is not None]:
                running.remove(case)
                assert case.proc is not None
                case.code = case.proc.returncode
                case.wall_s = time.monotonic() - case.began
                finished(case)
    finally:
        for case in running:
            _stop(case)


def run_cases(args: argparse.Namespace, cases: list[Case]) -> list[dict[str, Any]]:
    """Run the cases, ``args.jobs`` at once; return their summaries in case order."""
    results: dict[str, dict[str, Any]] = {}

    def finished(case: Case) -> None:
        results[case.name] = _case_summary(case)
        if not args.quiet:
            print(_progress(case, len(results), len(cases), results[case.name]), flush=True)

    run_launchers(cases, lambda case: _sim_args(args, case), args.jobs, finished)
    return [results[c.name] for c in cases]


def run_inprocess(args: argparse.Namespace, case: Case) -> dict[str, Any]:
    """One thesis case in this process (``deploy.engine``); its summary as the bus
    run's report would give it."""
    from deploy.engine import EngineCase, measures, run
    from report.thesis import PHASE_SSE_RAD, WORKLOAD_SSE_M2, thesis_cell

    began = time.monotonic()
    gmap, tr = run(EngineCase(
        map=case.map, robots=3, start=case.start, duration_s=args.duration, seed=args.seed,
        localization=args.localization or "truth", config=args.config,
        change=tuple(args.change),
        **{f: getattr(args, f) for f in ODOM_FLAGS if getattr(args, f) is not None}))
    summary: dict[str, Any] = {"map": case.map, "start": case.start}
    summary.update(measures(gmap, tr))
    if tr.frames:  # the map changed: how the team rebalanced after each change
        from deploy.engine import change_measures

        summary["changes"] = change_measures(gmap, tr)[1]
    summary["thesis_phase_sse_rad"] = thesis_cell(PHASE_SSE_RAD, case.map, case.start)
    summary["thesis_workload_sse_m2"] = thesis_cell(WORKLOAD_SSE_M2, case.map, case.start)
    wall = time.monotonic() - began
    summary["wall_s"] = round(wall, 1)
    summary["speedup"] = round(args.duration / wall, 1) if wall > 0 else None
    return summary  # no "dir": an in-process case writes no run directory


def _run_inprocess_all(args: argparse.Namespace, cases: list[Case]) -> list[dict[str, Any]]:
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(max(1, min(args.jobs, len(cases)))) as pool:
        pending = [pool.apply_async(run_inprocess, (args, c)) for c in cases]
        out = []
        for done, (case, job) in enumerate(zip(cases, pending, strict=True), start=1):
            summary = job.get()
            case.wall_s = summary["wall_s"]
            if not args.quiet:
                print(_progress(case, done, len(cases), summary), flush=True)
            out.append(summary)
    return out


def main(argv: list[str] | None = None) -> int:
    if argv and argv[0] == "general":
        from deploy.general import main as general

        return general(argv[1:])
    args = build_parser().parse_args(argv)
    if args.engine == "inprocess" and args.sensors == "lab":
        print("btrack suite: --sensors lab runs on the bus only (the in-process engine "
              "has the ideal sensors): use --engine bus", file=sys.stderr)
        return 2
    if args.engine == "inprocess" and args.localization not in (None, "truth", "odometry"):
        print("btrack suite: --engine inprocess takes truth or odometry poses (pf runs the "
              "localizer process: use --engine bus)", file=sys.stderr)
        return 2
    if args.jobs < 1 or not args.duration > 0:
        print("btrack suite: --jobs must be at least 1 and --duration positive",
              file=sys.stderr)
        return 2
    try:
        parse_changes(args.change)
    except ChangeError as exc:
        print(f"btrack suite: {exc}", file=sys.stderr)
        return 2
    out: Path = args.out or Path("runs") / time.strftime("suite-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    wanted = [(m, s) for m, s in all_cases() if m in args.maps and s in args.starts]
    cases = [Case(m, s, out / f"{m}_{s.replace(':', '')}") for m, s in wanted]
    if not args.quiet:
        print(f"btrack suite thesis: {len(cases)} cases of {args.duration:g} s, {args.jobs} "
              f"at once -> {out}", flush=True)
    began = time.monotonic()
    stop_on_sigterm()
    try:
        if args.engine == "inprocess":
            summaries = _run_inprocess_all(args, cases)
        else:
            summaries = run_cases(args, cases)
    except KeyboardInterrupt as exc:
        code, word = interrupted_code(exc)
        print(f"\nbtrack suite: {word}; every case stopped", file=sys.stderr)
        return code
    wall = time.monotonic() - began

    from report.suite import write_suite_report

    settings: dict[str, Any] = {
        "suite": "thesis", "engine": args.engine,
        "localization": args.localization or ("truth" if args.engine == "inprocess" else "default"),
        "duration_s": args.duration, "seed": args.seed, "jobs": args.jobs,
        "wall_s": round(wall, 1),
    }
    settings.update({f: getattr(args, f) for f in ODOM_FLAGS if getattr(args, f) is not None})
    below = write_suite_report(out, summaries, settings)
    failed = [s for s in summaries if "error" in s]
    if not args.quiet:
        print(f"btrack suite: {len(cases)} cases in {wall:.0f} s wall; "
              f"{below} of {len(cases)} below the thesis in both tables; "
              f"report {out / 'report.md'}")
    return 1 if failed else 0

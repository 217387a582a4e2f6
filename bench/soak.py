"""A long run with chaos: memory, the recording and the errors against simulated time.

Runs ``btrack sim --localization truth --chaos SEED`` for ``--hours`` simulated hours
(kills and restarts, freezes and thaws, joins: ``deploy.faults.chaos_schedule``) and,
while it runs, reads every process of the run from /proc every ``--every`` wall
seconds: its resident memory, by role (world, recorder, router, launcher, agent I; a
restarted agent is a new process under the same name). Afterwards it reads the
recording: the ticks' wall stamps put every reading on simulated time, and the
team's errors (position phase, eq. 3.1, and workload with the true depth, mean |e|
over the neighbour pairs) are averaged hour by hour. What was lost: ticks the
recording lacks against the run's, messages the processes dropped as malformed or
refused as implausible, and commands the world timed out on.

    .venv/bin/python bench/soak.py [--hours 24] [--robots 3] [--chaos 7] [--out DIR]
                                   [--wall-limit SECONDS]

How far behind the world the recorder was, tick by tick, comes from the recording
itself: each Tick carries the world's wall clock when it was sent and the recorder
stamps the wall clock when it took it off its channel. A recorder that grows while it
falls behind holds a backlog; one that grows while it keeps up leaks.

Writes DIR/readings.jsonl as it goes (a bench stopped by force leaves its readings),
DIR/soak.json (every reading, the hourly errors and lags, the counts) and DIR/soak.png,
and prints the table BENCHMARKS.md quotes: each process's memory at the end of hour 1
and at the end of the run, the recording's size, the errors and the recorder's lag by
hour, what was lost. ``--wall-limit`` (or Ctrl-C) ends the run early, as ``btrack sim``
ends on SIGTERM (the recorder finishes its file), and reports on the hours it reached.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from speed import world_summary  # noqa: E402
from tick_cpu import children_of  # noqa: E402

HOUR_S = 3600.0
DEFAULT_MAP = "half-algae"


def process_name(cmdline: list[str]) -> str:
    """A reading's name: ``agent 2``, ``world``, ``recorder``, ``router``, ``launcher``;
    ``other`` for anything else below the launcher."""
    at = next((i for i, a in enumerate(cmdline) if a == "btrack" or a.endswith("/btrack")),
              None)  # ``python -m btrack ...`` or ``.venv/bin/btrack ...``
    if at is None:
        return "other"
    args = cmdline[at + 1:]
    sub = args[0] if args else ""
    if sub == "agent" and "--id" in args:
        return f"agent {args[args.index('--id') + 1]}"
    return {"sim": "launcher", "record": "recorder"}.get(sub, sub or "other")


def read_rss_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None  # ended, or a zombie


def read_cmdline(pid: int) -> list[str]:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().decode(errors="replace").split("\0")
    except OSError:
        return []


def wall_to_sim(wall_ns: np.ndarray, tick_wall_ns: np.ndarray, tick_t: np.ndarray
                ) -> np.ndarray:
    """Each wall stamp on the run's simulated time, from the ticks' own wall stamps
    (NaN before the first tick; the last tick's time after the run)."""
    order = np.argsort(tick_wall_ns)
    w, t = tick_wall_ns[order].astype(float), tick_t[order]
    out = np.interp(wall_ns.astype(float), w, t)
    out[wall_ns < w[0]] = np.nan
    return np.asarray(out)


def hourly_means(t: np.ndarray, error: np.ndarray, hours: int) -> list[float]:
    """The mean of |error| (pairs x ticks, NaN where not a pair) within each simulated
    hour; NaN for an hour without a value."""
    out = []
    for h in range(hours):
        inside = (t >= h * HOUR_S) & (t < (h + 1) * HOUR_S)
        values = np.abs(error[:, inside])
        values = values[np.isfinite(values)]
        out.append(float(values.mean()) if values.size else math.nan)
    return out


def memory_at(readings: list[dict[str, Any]], sim_t: float) -> dict[str, float]:
    """Each process's last reading at or before simulated time ``sim_t``."""
    last: dict[str, float] = {}
    for r in readings:
        if math.isfinite(r["sim_t"]) and r["sim_t"] <= sim_t:
            last[r["name"]] = r["rss_mb"]
    return last


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench/soak.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--hours", type=float, default=24.0, help="simulated hours (24)")
    p.add_argument("--robots", type=int, default=3, help="team size (3)")
    p.add_argument("--map", default=DEFAULT_MAP, help=f"map ({DEFAULT_MAP})")
    p.add_argument("--chaos", type=int, default=7, help="seed of the chaos schedule (7)")
    p.add_argument("--every", type=float, default=5.0,
                   help="wall seconds between two readings of /proc (5)")
    p.add_argument("--wall-limit", type=float, metavar="SECONDS",
                   help="end the run after this much wall time and report on what it "
                        "reached (none: run the --hours)")
    p.add_argument("--out", type=Path, help="output directory (a fresh temporary one)")
    return p


def run_and_watch(args: argparse.Namespace, out: Path
                  ) -> tuple[list[dict[str, Any]], int, str]:
    """Run the team, reading /proc as it goes; the readings, the launcher's exit code
    and why the run ended early ("" if it ran its hours)."""
    btrack = str(Path(sys.executable).parent / "btrack")
    cmd = [btrack, "sim", "--robots", str(args.robots), "--map", args.map,
           "--localization", "truth", "--duration", str(args.hours * HOUR_S),
           "--chaos", str(args.chaos), "--no-report", "--no-scene", "--quiet",
           "--out", str(out)]
    readings: list[dict[str, Any]] = []
    names: dict[int, str] = {}
    recording = out / "run.mcap"
    began = time.monotonic()
    ended_early = ""
    with open(out / "launcher.log", "wb") as log, open(out / "readings.jsonl", "w") as stream:
        launcher = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        try:
            next_report = began + 60
            while launcher.poll() is None:
                now_ns = time.time_ns()
                taken = []
                for pid in children_of(launcher.pid):
                    if pid not in names:
                        names[pid] = process_name(read_cmdline(pid))
                    rss = read_rss_mb(pid)
                    if rss is not None and names[pid] != "other":
                        taken.append({"wall_ns": now_ns, "pid": pid, "name": names[pid],
                                      "rss_mb": rss})
                size = recording.stat().st_size if recording.exists() else 0
                taken.append({"wall_ns": now_ns, "pid": 0, "name": "recording",
                              "rss_mb": size / 2**20})
                readings += taken
                stream.writelines(json.dumps(r) + "\n" for r in taken)
                stream.flush()
                now = time.monotonic()
                if now >= next_report:
                    print(f"  {now - began:.0f} s: {len(readings)} readings, recording "
                          f"{size / 2**20:.0f} MB", file=sys.stderr, flush=True)
                    next_report += 60
                if args.wall_limit is not None and now - began >= args.wall_limit:
                    ended_early = f"the wall limit of {args.wall_limit:g} s"
                    break
                time.sleep(args.every)
        except KeyboardInterrupt:
            ended_early = "Ctrl-C"
        finally:
            if launcher.poll() is None:
                # as Ctrl-C would: the launcher stops every process, the recorder
                # finishes its file
                launcher.send_signal(signal.SIGINT)
            try:
                code = launcher.wait(60)
            except subprocess.TimeoutExpired:
                launcher.kill()
                code = launcher.wait()
    return readings, code, ended_early


def recorder_lag(run: Any) -> np.ndarray:
    """Seconds by which the recorder took each tick after the world sent it (NaN where
    the world gave no wall clock)."""
    sent = np.asarray(run.tick_log_ns, dtype=np.int64)
    taken = np.asarray(run.tick_recorded_ns, dtype=np.int64)
    lag = (taken - sent).astype(float) / 1e9
    lag[taken == sent] = np.nan  # tick_log_ns fell back on the recorder's own stamp
    return lag


def hourly_lag(t: np.ndarray, lag: np.ndarray, hours: int) -> list[dict[str, float]]:
    """The recorder's lag within each simulated hour: its median and its worst."""
    out = []
    for h in range(hours):
        values = lag[(t >= h * HOUR_S) & (t < (h + 1) * HOUR_S)]
        values = values[np.isfinite(values)]
        out.append({"median_s": float(np.median(values)) if values.size else math.nan,
                    "max_s": float(values.max()) if values.size else math.nan})
    return out


def analyse(args: argparse.Namespace, out: Path, readings: list[dict[str, Any]]
            ) -> dict[str, Any]:
    from report.load import load_run
    from report.series import run_table

    run = load_run(out / "run.mcap")
    tick_t = np.asarray(run.tick_t, dtype=float)
    tick_wall = np.asarray(run.tick_log_ns, dtype=np.int64)
    sims = wall_to_sim(np.array([r["wall_ns"] for r in readings], dtype=np.int64),
                       tick_wall, tick_t)
    for r, s in zip(readings, sims, strict=True):
        r["sim_t"] = float(s)
    end_t = float(tick_t[-1]) if tick_t.size else 0.0
    hours = max(1, math.ceil((end_t + 0.1) / HOUR_S - 1e-9))
    errors = run_table(run).errors
    lag = recorder_lag(run)
    # the ticks from the first to the last recorded (a run ended early: those it reached)
    expected = round(end_t / 0.1) + 1 if tick_t.size else 0
    lost = {"ticks_recorded": int(tick_t.size), "ticks_expected": expected,
            "invalid_recorded": run.invalid, "rejected_recorded": sum(run.rejected.values()),
            "refused": run.refused, "recording_cut_short": run.cut_short}
    try:
        world = world_summary(out)
        lost.update({f"world_{k}": world.get(k) for k in ("dropped", "rejected", "timeouts")})
    except (OSError, ValueError, StopIteration) as exc:
        lost["world_summary"] = f"not read: {exc}"
    step = max(1, lag.size // 4000)  # the lag series as the figure draws it
    return {
        "hours": args.hours, "hours_reached": end_t / HOUR_S, "robots": args.robots,
        "map": args.map, "chaos": args.chaos, "faults": len(run.faults),
        "memory_hour_1": memory_at(readings, HOUR_S),
        "memory_end": memory_at(readings, end_t),
        "phase_by_hour_rad": hourly_means(errors.t, errors.phase, hours),
        "workload_by_hour_m2": hourly_means(errors.t, errors.workload, hours),
        "recorder_lag_by_hour": hourly_lag(tick_t, lag, hours),
        "recorder_lag": {"t": tick_t[::step].tolist(),
                         "lag_s": [None if not math.isfinite(v) else round(v, 3)
                                   for v in lag[::step]]},
        "lost": lost, "readings": readings,
    }


def figure(result: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (mem, rec, behind, err) = plt.subplots(4, 1, figsize=(9, 11), sharex=True)
    by_name: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for r in result["readings"]:
        if math.isfinite(r["sim_t"]):
            by_name[r["name"]].append((r["sim_t"] / HOUR_S, r["rss_mb"]))
    for name, points in sorted(by_name.items()):
        ax = rec if name == "recording" else mem
        ax.plot(*zip(*points, strict=True), ".", markersize=2, label=name)
    mem.set_ylabel("resident MB")
    mem.legend(fontsize=7, ncol=4)
    rec.set_ylabel("run.mcap MB")
    lag = result["recorder_lag"]
    behind.plot(np.asarray(lag["t"]) / HOUR_S,
                [math.nan if v is None else v for v in lag["lag_s"]], lw=0.7)
    behind.set_ylabel("recorder behind, s")
    hours = np.arange(len(result["phase_by_hour_rad"])) + 0.5
    err.plot(hours, result["phase_by_hour_rad"], "o-", label="position phase, rad")
    err.plot(hours, result["workload_by_hour_m2"], "s-", label="workload, m^2")
    err.set_yscale("log")
    err.set_xlabel("simulated hours")
    err.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def table(result: dict[str, Any]) -> str:
    one, end = result["memory_hour_1"], result["memory_end"]
    lines = ["| process | MB at hour 1 | MB at the end |", "| --- | --- | --- |"]
    for name in sorted(set(one) | set(end)):
        lines.append(f"| {name} | {one.get(name, math.nan):.1f} | {end.get(name, math.nan):.1f} |")
    lines += ["", "| hour | position phase rad | workload m^2 | recorder behind, median s "
              "| worst s |", "| --- | --- | --- | --- | --- |"]
    for h, (p, w, lag) in enumerate(zip(result["phase_by_hour_rad"],
                                        result["workload_by_hour_m2"],
                                        result["recorder_lag_by_hour"], strict=True)):
        lines.append(f"| {h + 1} | {p:.4f} | {w:.4f} | {lag['median_s']:.2f} "
                     f"| {lag['max_s']:.2f} |")
    lines += ["", "lost: " + json.dumps(result["lost"]) + f"; faults injected: {result['faults']}"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not (args.hours > 0 and args.robots >= 2 and args.every > 0
            and (args.wall_limit is None or args.wall_limit > 0)):
        print("bench/soak.py: --hours, --every and --wall-limit must be positive, --robots "
              "at least 2", file=sys.stderr)
        return 2
    out = args.out or Path(tempfile.mkdtemp(prefix="soak-"))
    out.mkdir(parents=True, exist_ok=True)
    began = time.monotonic()
    readings, code, ended_early = run_and_watch(args, out)
    if ended_early:
        print(f"bench/soak.py: run ended early by {ended_early}; reporting what it reached",
              file=sys.stderr)
    elif code != 0:
        print(f"bench/soak.py: btrack sim exited {code}; see {out}/launcher.log",
              file=sys.stderr)
    result = analyse(args, out, readings)
    result["wall_s"] = round(time.monotonic() - began, 1)
    result["sim_exit"] = code
    result["ended_early"] = ended_early
    (out / "soak.json").write_text(json.dumps(result, indent=1, allow_nan=True) + "\n")
    figure(result, out / "soak.png")
    print(table(result))
    print(f"{result['hours_reached']:.2f} simulated hours in {result['wall_s']} s of wall "
          f"time; {out}/soak.json, {out}/soak.png")
    return 0 if code == 0 or ended_early else 1


if __name__ == "__main__":
    sys.exit(main())

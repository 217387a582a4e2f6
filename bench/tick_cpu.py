"""A tick's CPU, process by process, and what the world and one agent spend it on.

Runs ``btrack sim --localization truth`` for each team size and, while it runs, reads
every process of the run from /proc (each is a child of the launcher): the CPU time
of its main thread (the Python loop) and of its other threads (Zenoh's runtime, with
the subscriber callbacks it runs), and its resident memory. A process's CPU is counted
from the world's first tick to the process's end (the recorder's catch-up included),
over the run's ticks.

With ``--profile`` a second run of each size runs the world and agent 0 under cProfile
timed by thread CPU (``time.thread_time``), and splits their main thread's CPU per tick
into decoding, encoding, the Zenoh put, the control step and the rest. Profiling slows
the profiled process, so that run's speed is not the team's; its shares are the figure.

    .venv/bin/python bench/tick_cpu.py [--robots 3 30] [--duration 60] [--profile]
"""

from __future__ import annotations

import argparse
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from lockstep import DEFAULT_MAP, DT_S, load, positive_float, team_size  # noqa: E402
from speed import sim_command, world_summary  # noqa: E402

TICKS_PER_S = os.sysconf("SC_CLK_TCK")
PSS_EVERY = 20  # readings of /proc between two of PSS
ROLES = ("world", "agent", "localizer", "recorder", "launcher", "other")
PROFILE_ENV = "BTRACK_BENCH_PROFILE"  # where the profiled processes write their stats
# Imported by every Python process of a profiled run (it is on their PYTHONPATH): it
# profiles the world and agent 0 and writes their stats when they exit.
SITECUSTOMIZE = f'''\
import atexit, cProfile, os, sys, time
_dir = os.environ.get("{PROFILE_ENV}")
_who = sys.argv[1:4]
if _dir and _who[:1] == ["world"] or _dir and _who == ["agent", "--id", "0"]:
    _profile = cProfile.Profile(time.thread_time)
    _name = os.path.join(_dir, _who[0] + ".prof")
    def _dump():
        _profile.disable()
        _profile.dump_stats(_name)
    atexit.register(_dump)
    _profile.enable()
'''


@dataclass
class Sampled:
    """One process of the run as /proc showed it: CPU seconds at each sample."""

    pid: int
    role: str
    cmdline: list[str]
    samples: list[tuple[float, float, float]] = field(default_factory=list)  # wall, all, main
    rss_mb: float = 0.0
    anon_mb: float = 0.0
    pss_mb: float = 0.0  # its share of the pages it shares (the libraries), plus its own
    threads: int = 0

    def cpu_since(self, t0: float) -> tuple[float, float]:
        """CPU seconds (all threads, main thread) from wall time t0 to the last sample."""
        before = [s for s in self.samples if s[0] <= t0] or self.samples[:1]
        first, last = before[-1], self.samples[-1]
        return last[1] - first[1], last[2] - first[2]


def role_of(cmdline: list[str]) -> str:
    if "btrack" in cmdline:
        sub = cmdline[cmdline.index("btrack") + 1:][:1]
        name = {"sim": "launcher", "record": "recorder"}.get(sub[0] if sub else "", "")
        return name or (sub[0] if sub and sub[0] in ROLES else "other")
    return "other"


def read_cpu(path: str) -> float:
    """utime + stime of a /proc stat file, in seconds."""
    with open(path) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def children_of(root: int) -> set[int]:
    """``root`` and every process below it."""
    parent: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parent[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
    found, grew = {root}, True
    while grew:
        more = {pid for pid, ppid in parent.items() if ppid in found} - found
        found |= more
        grew = bool(more)
    return found


def sample(root: int, seen: dict[int, Sampled], rollup: bool) -> None:
    """One reading of every process below ``root``; with ``rollup`` also its PSS (that
    walks its page tables, so it is read seldom)."""
    now = time.monotonic()
    for pid in children_of(root):
        try:
            if pid not in seen:
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    cmdline = f.read().decode(errors="replace").split("\0")
                seen[pid] = Sampled(pid, role_of(cmdline), cmdline)
            proc = seen[pid]
            total = read_cpu(f"/proc/{pid}/stat")
            main = read_cpu(f"/proc/{pid}/task/{pid}/stat")
            status = dict(line.split(":", 1) for line in open(f"/proc/{pid}/status"))
        except (OSError, ValueError):
            continue  # it has just ended
        proc.samples.append((now, total, main))
        if "VmRSS" not in status:
            continue  # a zombie: its CPU is still there, its memory is gone
        proc.rss_mb = int(status["VmRSS"].split()[0]) / 1024
        proc.anon_mb = int(status["RssAnon"].split()[0]) / 1024
        proc.threads = int(status["Threads"])
        if rollup:
            try:
                with open(f"/proc/{pid}/smaps_rollup") as f:
                    pss = next(line for line in f if line.startswith("Pss:"))
                proc.pss_mb = int(pss.split()[1]) / 1024
            except (OSError, StopIteration):
                pass


def timed_run(n: int, args: argparse.Namespace, profile_dir: str | None
              ) -> tuple[dict[int, Sampled], dict[str, float | int], float]:
    """One run with every process sampled; its processes, the world's summary and the
    wall time of the world's first tick."""
    env = dict(os.environ, **dict(kv.split("=", 1) for kv in args.env))
    if profile_dir:
        (Path(profile_dir) / "sitecustomize.py").write_text(SITECUSTOMIZE)
        env[PROFILE_ENV] = profile_dir
        env["PYTHONPATH"] = os.pathsep.join(p for p in (profile_dir, env.get("PYTHONPATH"))
                                            if p)
    seen: dict[int, Sampled] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        launcher = subprocess.Popen(sim_command(n, args.duration, args.map, "truth", out),
                                    stdout=subprocess.DEVNULL, env=env)
        try:
            readings = 0
            while launcher.poll() is None:
                sample(launcher.pid, seen, readings % PSS_EVERY == 0)
                readings += 1
                time.sleep(args.sample_s)
        finally:
            if launcher.poll() is None:
                launcher.terminate()
                launcher.wait(30)
        if launcher.returncode != 0:
            raise SystemExit(f"bench: btrack sim exited with {launcher.returncode}")
        summary = world_summary(out)
    world = next(p for p in seen.values() if p.role == "world")
    # the world ends at its last tick: its first was wall_s before
    first_tick = world.samples[-1][0] - float(summary["wall_s"])
    return seen, summary, first_tick


def profile_split(path: Path, ticks: int) -> dict[str, float]:
    """A profiled main thread's CPU ms per tick by cost, from its cProfile stats."""
    stats = pstats.Stats(str(path)).stats  # type: ignore[attr-defined]
    costs = {"decode": 0.0, "encode": 0.0, "put": 0.0, "control": 0.0, "wait": 0.0,
             "loop": 0.0}
    for (file, _, name), (_, _, _, cumulative, _) in stats.items():
        if file.endswith(os.path.join("wire", "codec.py")) and name in ("decode", "encode"):
            costs[name] += cumulative
        elif "'put' of 'builtins.Publisher'" in name or "'put' of 'zenoh" in name:
            costs["put"] += cumulative
        elif name == "step" and (file.endswith(os.path.join("agent", "controller.py"))
                                 or file.endswith(os.path.join("simworld", "world.py"))):
            costs["control"] += cumulative
        elif "'get' of '_queue.SimpleQueue'" in name:
            costs["wait"] += cumulative  # the wake-ups: a thread blocked spends no CPU
        elif name in ("run", "run_lockstep") and (file.endswith("process.py")):
            costs["loop"] += cumulative
    costs["other"] = costs["loop"] - sum(costs[k] for k in
                                         ("decode", "encode", "put", "control", "wait"))
    return {k: 1000.0 * v / ticks for k, v in costs.items()}


def print_processes(n: int, seen: dict[int, Sampled], ticks: int, first_tick: float) -> None:
    print(f"\n{n} robots: CPU ms per tick from the first tick to each process's end; "
          "resident MB at the last sample")
    print("| process | count | CPU ms/tick (all) | main thread | other threads "
          "| RSS MB (each, median) | anon MB | PSS MB | threads |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    grand = 0.0
    for role in ROLES:
        procs = [p for p in seen.values() if p.role == role and p.samples]
        if not procs:
            continue
        cpu = [p.cpu_since(first_tick) for p in procs]
        whole = sum(c[0] for c in cpu) * 1000.0 / ticks
        main = sum(c[1] for c in cpu) * 1000.0 / ticks
        grand += whole
        each = f" ({whole / len(procs):.3f} each)" if len(procs) > 1 else ""
        print(f"| {role} | {len(procs)} | {whole:.3f}{each} | {main:.3f} | {whole - main:.3f} "
              f"| {statistics.median(p.rss_mb for p in procs):.1f} "
              f"| {statistics.median(p.anon_mb for p in procs):.1f} "
              f"| {statistics.median(p.pss_mb for p in procs):.1f} "
              f"| {statistics.median(p.threads for p in procs):.0f} |")
    print(f"| all | {len(seen)} | {grand:.3f} | | | | | | |")


def env_setting(text: str) -> str:
    name, eq, _ = text.partition("=")
    if not eq or not name.isidentifier():
        raise argparse.ArgumentTypeError(f"not NAME=VALUE: {text!r}")
    return text


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                epilog="Run from the repository's root.")
    p.add_argument("--robots", type=team_size, nargs="+", default=[3, 30],
                   help="team sizes (default 3 30)")
    p.add_argument("--duration", type=positive_float, default=60.0,
                   help="simulated seconds a run (default 60: 600 ticks)")
    p.add_argument("--map", default=DEFAULT_MAP, help="the team's map (default: a 30 m "
                   "straight procedural edge)")
    p.add_argument("--profile", action="store_true",
                   help="also a run of each size with the world and agent 0 under cProfile")
    p.add_argument("--env", action="append", default=[], metavar="NAME=VALUE",
                   type=env_setting, help="set in the run's environment, e.g. "
                   "ZENOH_CONFIG=FILE.json5 or MALLOC_ARENA_MAX=2 (repeatable)")
    p.add_argument("--top", type=int, default=0, metavar="N",
                   help="with --profile: also print each profile's N costliest functions")
    p.add_argument("--sample-s", type=positive_float, default=0.1,
                   help="wall seconds between two readings of /proc (default 0.1)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    for n in args.robots:
        print(f"bench: {n} robots, {args.duration:g} s simulated; load {load()}", flush=True)
        seen, summary, first_tick = timed_run(n, args, None)
        ticks = int(summary["ticks"])
        print(f"bench: {ticks} ticks at {ticks / float(summary['wall_s']):.0f} ticks/s "
              f"({float(summary['speedup']):.1f}x); load {load()}", flush=True)
        print_processes(n, seen, ticks, first_tick)
        if not args.profile:
            continue
        with tempfile.TemporaryDirectory() as prof:
            print(f"\nbench: {n} robots again, world and agent 0 under cProfile; "
                  f"load {load()}", flush=True)
            seen, summary, first_tick = timed_run(n, args, prof)
            ticks = int(summary["ticks"])
            print(f"bench: {ticks / float(summary['wall_s']):.0f} ticks/s under the profiler; "
                  f"load {load()}")
            print("| process | decode | encode | Zenoh put | control step | queue wake-ups "
                  "| rest of the loop | main thread by /proc | other threads by /proc |")
            print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
            for who in ("world", "agent"):
                path = Path(prof) / f"{who}.prof"
                if not path.exists():
                    print(f"| {who} | no profile written | | | | | | | |")
                    continue
                ms = profile_split(path, ticks)
                proc = next(p for p in seen.values() if p.role == who and p.samples
                            and (who == "world" or "--id 0 " in " ".join(p.cmdline)))
                whole, main_cpu = proc.cpu_since(first_tick)
                print(f"| {who}{' 0' if who == 'agent' else ''} | {ms['decode']:.3f} "
                      f"| {ms['encode']:.3f} | {ms['put']:.3f} | {ms['control']:.3f} "
                      f"| {ms['wait']:.3f} | {ms['other']:.3f} | {1000 * main_cpu / ticks:.3f} "
                      f"| {1000 * (whole - main_cpu) / ticks:.3f} |")
            print("(ms of CPU per tick; the control step of the world is its physics)")
            for who in ("world", "agent") if args.top > 0 else ():
                path = Path(prof) / f"{who}.prof"
                if path.exists():
                    print(f"\n{who}'s {args.top} costliest functions (own time):")
                    pstats.Stats(str(path)).sort_stats("tottime").print_stats(args.top)
    print(f"\nload average at the end: {load()}; {DT_S:g} s a tick")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

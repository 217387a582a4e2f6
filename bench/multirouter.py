"""A team across hosts behind a mesh of Zenoh routers, and one of the routers killed and
restarted (issue 21, item 5).

Hosts are Linux network namespaces on one switch (``tests.netns.Mesh``). Host k runs
router k; host 0 also the world and the recorder (the base station). Robot i's agent
runs on host i mod K and is a client of its host's router first and of the others, in
turn, after it, so the neighbours of a robot are behind other routers and every state
crosses the mesh. The routers' and the agents' configurations are what ``btrack deploy
render`` writes for a fleet file with ``[[routers]]`` (a robot's ``router = i mod K``),
its certificates what ``btrack deploy certs`` makes: every link is mutual TLS with the
fleet's access control on every router, which also lets the other routers of the mesh
route (``deploy.render.mesh_router_config``). At ``--kill-at`` router
``--kill`` is killed (SIGKILL: its links drop at once), at ``--restart-at`` started again;
or, with ``--fault freeze``, stopped (SIGSTOP: a host that hangs without a word, its
links open and silent, found out only by the lease) and at ``--restart-at`` let go on
(SIGCONT).

An observer in the caller's namespace (the operator's laptop, with the recorder's
certificate) hears the world's ticks and the agents' states, stamped with its wall
clock. It writes ``OUT/measured.json``:

- ``phase_before_kill_rad``: the position phase error (eq. 3.1, from the recording:
  mean |e| over the pairs) over the 10 simulated seconds before the kill, and
  ``phase_last_quarter_rad`` over the run's last quarter;
- ``silence_max_s``: the longest the observer heard nothing from a robot of the killed
  router after the kill; ``links_*``: how many agents held their link to each router
  before the kill, before the restart and near the end (from ``ss`` on each host);
- ``detected_s``: wall seconds from the kill until the world's tick no longer lists the
  killed router's robots; ``back_s``: until it lists every robot again;
- ``unowned_max_s``: after the kill, the longest wall time during which the latest
  segments of the robots the world lists leave a stretch of the edge over 5 cm
  without an owner;
- ``tiled_at_end``: the last states tile the edge, in order, every robot live;
- ``phase_minute_after_kill_worst_rad``: the worst pair's position phase error in the
  60 simulated s from the fault, ``pairs_over_band_minute_after_kill`` how many pairs
  passed 0.05 rad then; ``states_skipping_a_neighbour``: states heard after the fault
  naming a neighbour other than the next id (a robot taken for gone).

Needs root (``ip netns``); says why and exits 2 where namespaces cannot be made.

    sudo .venv/bin/python bench/multirouter.py --robots 100 --routers 3 --out runs/mesh100
    .venv/bin/python bench/multirouter.py --robots 6 --routers 3 --realtime --duration 60 \\
        --kill-at 25 --restart-at 40 --out /tmp/mesh6    # what tests/test_multirouter.py runs
    .venv/bin/python bench/multirouter.py --robots 6 --routers 3 --realtime --duration 60 \
        --kill-at 25 --restart-at 40 --fault freeze --out /tmp/mesh6f   # ... and this too
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from deploy.certs import make_fleet_certs  # noqa: E402
from deploy.fleet import Fleet, parse  # noqa: E402
from deploy.render import MESH_TOKEN_GRACE_S, client_config, render  # noqa: E402
from tests import netns  # noqa: E402

PORT = 7447
GAP_M = 0.05  # a stretch of the edge this long without an owner is unowned


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench/multirouter.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--robots", type=int, default=100)
    p.add_argument("--routers", type=int, default=3, help="routers meshed, one a host (3)")
    p.add_argument("--map", default=None,
                   help="default: a straight edge with no algae, 0.6 m a robot (at least 3 m)")
    p.add_argument("--duration", type=float, default=300.0, help="simulated s (300)")
    p.add_argument("--kill-at", type=float, default=120.0, help="simulated s (120)")
    p.add_argument("--restart-at", type=float, default=180.0, help="simulated s (180)")
    p.add_argument("--kill", type=int, default=None, help="which router (the last)")
    p.add_argument("--fault", choices=("kill", "freeze"), default="kill",
                   help="kill: SIGKILL at --kill-at, started again at --restart-at; freeze: "
                   "SIGSTOP, then SIGCONT (default kill)")
    p.add_argument("--realtime", action="store_true",
                   help="the world paces ticks on the wall clock (default: lockstep)")
    p.add_argument("--lease", type=float, default=1.0, help="the robots' lease, s (1)")
    p.add_argument("--cycle-s", type=float, default=None,
                   help="fix the team's cycle (default: from the team's need)")
    p.add_argument("--start", default="in-phase", help="the world's --start (in-phase)")
    p.add_argument("--token-grace", type=float, default=MESH_TOKEN_GRACE_S, metavar="S",
                   help="the agents' --token-grace, as btrack deploy render gives a "
                   f"meshed fleet ({MESH_TOKEN_GRACE_S:g}; 0: a neighbour whose token goes "
                   "is dropped at once)")
    p.add_argument("--startup-timeout", type=float, default=300.0,
                   help="wall s the world waits for every agent (300)")
    p.add_argument("--wall-limit", type=float, default=3600.0,
                   help="give up after this many wall seconds (3600)")
    p.add_argument("--out", type=Path, required=True)
    return p


class MeshTeam:
    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.out: Path = args.out
        self.k = args.routers
        self.n = args.robots
        self.kill = self.k - 1 if args.kill is None else args.kill
        self.mesh = netns.Mesh(self.k, self.out / "logs")
        self.ns = f"mesh{self.mesh.switch_ns[2:8]}"
        length = max(3.0, round(0.6 * self.n, 2))
        self.map = args.map or (f"procedural:1,length={length:g},edge=straight,"
                                "amplitude=0,algae=none")
        self.seen: netns.Observer | None = None
        self.routers: dict[int, Any] = {}
        self.router_conf: dict[int, str] = {}
        self.world: Any = None
        self.recorder: Any = None
        self.agents: dict[int, Any] = {}
        self.kill_wall: float | None = None
        self.restart_wall: float | None = None
        self.kill_t: float | None = None
        # which router each agent's link went to, sampled before the kill, before the
        # restart and near the end (``connections``)
        self.links: dict[str, dict[int, int | None]] = {}

    def host_of(self, rid: int) -> int:
        return rid % self.k

    def fleet(self) -> Fleet:
        """The fleet file of the run: router k on host k's address, robot i behind
        router i mod K."""
        robots = "".join(f'[[robots]]\nid = {i}\nhost = "robot{i}"\nrouter = {self.host_of(i)}\n'
                         for i in range(self.n))
        routers = "".join(f'[[routers]]\nhost = "{self.mesh.addr(k)}"\n'
                          for k in range(1, self.k))
        return parse(f'namespace = "{self.ns}"\nlease_s = {self.args.lease}\n[base]\n'
                     f'host = "{self.mesh.addr(0)}"\nport = {PORT}\n'
                     f'[tls]\ndir = "{self.out / "tls"}"\n{routers}{robots}')

    def write(self, name: str, conf: dict[str, Any] | str) -> str:
        path = self.out / "conf" / f"{name}.json5"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(conf if isinstance(conf, str) else json.dumps(conf, indent=1))
        return str(path)

    def start(self) -> None:
        mesh, out = self.mesh, self.out
        mesh.up()
        fleet = self.fleet()
        make_fleet_certs(fleet, out / "tls", flat=True)
        rendered = render(fleet)
        cd = fleet.config_dir.strip("/")
        for k, host in enumerate(fleet.router_hosts):
            self.router_conf[k] = self.write(f"router{k}",
                                             rendered[f"{host}/{cd}/zenoh-router.json5"])
        for k in range(self.k):
            self.start_router(k)
        base = mesh.addr(0)
        world, recorder = (self.write(role, client_config(fleet, role, host=base))
                           for role in ("world", "recorder"))
        common = ["--ns", self.ns]
        self.recorder = mesh.start(0, "recorder", ["record", "--out", str(out),
                                                   "--zenoh-config", recorder, *common])
        self.seen = netns.Observer(client_config(fleet, "recorder", host=base), self.ns, 60.0)
        agent_args = ["--robots", str(self.n)]
        if self.args.realtime:
            agent_args += ["--neighbour-timeout", "0"]
        if self.args.cycle_s:
            agent_args += ["--cycle-s", repr(self.args.cycle_s)]
        if self.args.token_grace:
            agent_args += ["--token-grace", repr(self.args.token_grace)]
        for i in range(self.n):
            k = self.host_of(i)
            conf = self.write(f"agent{i}", rendered[f"robot{i}/{cd}/zenoh-agent-{i}.json5"])
            self.agents[i] = mesh.start(k, f"agent{i}", ["agent", "--id", str(i),
                                                         *agent_args, "--zenoh-config", conf,
                                                         *common])
        world_args = ["world", "--robots", str(self.n), "--map", self.map, "--start",
                      self.args.start, "--localization", "truth", "--duration",
                      repr(self.args.duration), "--wait-recorder", "--startup-timeout",
                      repr(self.args.startup_timeout), "--zenoh-config", world, *common]
        if self.args.realtime:
            world_args.append("--realtime")
        self.world = mesh.start(0, "world", world_args)

    def start_router(self, k: int) -> None:
        self.routers[k] = self.mesh.start(k, f"router{k}" + ("-again" if k in self.routers
                                                             else ""),
                                          ["router", "--zenoh-config", self.router_conf[k]])

    def connections(self) -> dict[int, int | None]:
        """Which router each agent holds its link to now, from ``ss`` on its host: the
        router whose address its TCP connection to the port goes to (None: none)."""
        pids = {p.pid: rid for rid, p in self.agents.items() if p.poll() is None}
        by_addr = {self.mesh.addr(k): k for k in range(self.k)}
        out: dict[int, int | None] = dict.fromkeys(range(self.n))
        for ns in self.mesh.host_ns:
            res = subprocess.run(["ip", "netns", "exec", ns, "ss", "-tnpH", "state",
                                  "established"], capture_output=True, text=True, timeout=30)
            for line in res.stdout.splitlines():
                cols = line.split()
                if len(cols) < 5 or not cols[3].endswith(f":{PORT}"):
                    continue
                for pid, rid in pids.items():
                    if f"pid={pid}," in line:
                        out[rid] = by_addr.get(cols[3].rsplit(":", 1)[0])
        return out

    def run(self) -> int:
        """Start, kill and restart the router on time, wait for the world; its code."""
        began = time.monotonic()
        last_print = began
        freeze = self.args.fault == "freeze"
        while self.world.poll() is None:
            if time.monotonic() - began > self.args.wall_limit:
                print("multirouter: the wall limit came first", file=sys.stderr)
                return 1
            t = self.observed().last_t()
            if self.kill_wall is None and t >= self.args.kill_at:
                self.links["before_kill"] = self.connections()
                self.routers[self.kill].send_signal(signal.SIGSTOP if freeze
                                                    else signal.SIGKILL)
                self.kill_wall, self.kill_t = time.monotonic(), t
                print(f"multirouter: t = {t:.1f} s: router {self.kill} "
                      f"{'frozen' if freeze else 'killed'}", flush=True)
            elif (self.kill_wall is not None and self.restart_wall is None
                  and t >= self.args.restart_at):
                self.links["before_restart"] = self.connections()
                if freeze:
                    self.routers[self.kill].send_signal(signal.SIGCONT)
                else:
                    self.routers[self.kill].wait(5)
                    self.start_router(self.kill)
                self.restart_wall = time.monotonic()
                print(f"multirouter: t = {t:.1f} s: router {self.kill} "
                      f"{'let go on' if freeze else 'started again'}", flush=True)
            if "at_end" not in self.links and t >= self.args.duration - 3.0:
                self.links["at_end"] = self.connections()
            if time.monotonic() - last_print > 30:
                last_print = time.monotonic()
                print(f"multirouter: t = {t:.1f} s of {self.args.duration:g}, "
                      f"{last_print - began:.0f} s of wall time", flush=True)
            time.sleep(0.02)
        return int(self.world.returncode)

    def close(self) -> None:
        if self.recorder is not None:
            try:
                self.recorder.wait(60)
            except Exception:
                pass
        if self.seen is not None:
            self.seen.close()
        self.mesh.close()

    def observed(self) -> netns.Observer:
        assert self.seen is not None, "the observer opens as the team starts"
        return self.seen


def unowned_max(ticks: list, states: list, since: float, edge: tuple[float, float],
                n: int) -> float:
    """The longest wall time after ``since`` that the latest segments of the robots the
    latest tick lists leave a stretch over GAP_M of ``edge`` unowned."""
    events = sorted([(r[0], 0, r) for r in ticks] + [(r[0], 1, r) for r in states],
                    key=lambda e: e[0])
    latest: dict[int, tuple[float, float]] = {}
    live: tuple[int, ...] = tuple(range(n))
    worst, gap_from = 0.0, None
    for wall, kind, row in events:
        if kind == 0:
            live = row[2]
        else:
            latest[row[2]] = (row[3], row[4])
        if wall < since:
            continue
        segs = sorted(latest[i] for i in live if i in latest)
        covered, reach = bool(segs), edge[0]
        for lo, hi in segs:
            if lo > reach + GAP_M:
                covered = False
                break
            reach = max(reach, hi)
        covered = covered and reach >= edge[1] - GAP_M
        if not covered and gap_from is None:
            gap_from = wall
        elif covered and gap_from is not None:
            worst, gap_from = max(worst, wall - gap_from), None
    if gap_from is not None:
        worst = max(worst, events[-1][0] - gap_from)
    return worst


PHASE_BAND_RAD = 0.05  # the position phase goal


def measures(team: MeshTeam) -> dict[str, Any]:
    import numpy as np

    from report.load import load_run
    from report.series import error_series

    seen, n = team.observed(), team.n
    out: dict[str, Any] = {"robots": n, "routers": team.k, "killed_router": team.kill,
                           "fault": team.args.fault, "map": team.map,
                           "token_grace_s": team.args.token_grace,
                           "realtime": team.args.realtime,
                           "ticks_seen": len(seen.ticks), "states_seen": len(seen.states)}
    s = error_series(load_run(team.out / "run.mcap"))
    phase = np.abs(s.phase)
    end = float(s.t[-1])
    if team.kill_t is not None:
        before = (s.t >= team.kill_t - 10.0) & (s.t < team.kill_t)
        out["phase_before_kill_rad"] = float(np.nanmean(phase[:, before]))
        # what the fault did to a converged team: the minute after it, pair by pair
        minute = (s.t >= team.kill_t) & (s.t < team.kill_t + 60.0)
        if minute.any():
            worst = np.nanmax(phase[:, minute], axis=1)
            out["phase_minute_after_kill_worst_rad"] = float(np.nanmax(worst))
            out["pairs_over_band_minute_after_kill"] = int(np.sum(worst > PHASE_BAND_RAD))
    out["phase_last_quarter_rad"] = float(np.nanmean(phase[:, s.t >= 0.75 * end]))
    out["simulated_s"] = end
    killed = {i for i in range(n) if team.host_of(i) == team.kill}
    if team.kill_wall is not None:
        kw = team.kill_wall
        out["detected_s"] = next((r[0] - kw for r in seen.ticks
                                  if r[0] >= kw and not killed & set(r[2])), None)
        out["dropped_from_live"] = out["detected_s"] is not None
        # the longest the observer heard nothing from a robot of the killed router
        silence = []
        for rid in killed:
            walls = [r[0] for r in seen.states if r[2] == rid and r[0] >= kw - 1.0]
            silence.append(max((b - a for a, b in zip(walls, walls[1:], strict=False)),
                               default=math.inf))
        out["silence_max_s"] = max(silence, default=None)
        out["back_s"] = next((r[0] - kw for r in seen.ticks if r[0] >= kw
                              and out["detected_s"] is not None
                              and r[0] - kw > out["detected_s"] and len(r[2]) == n), None)
        out["robots_on_killed_router"] = len(killed)
        from simworld.maps import load_map

        gmap = load_map(team.map)
        out["unowned_max_s"] = unowned_max(seen.ticks, seen.states, kw,
                                           (gmap.edge_lo, gmap.edge_hi), n)
    if team.restart_wall is not None and seen.ticks:
        after = [r for r in seen.ticks if r[0] >= team.restart_wall]
        out["ticks_after_restart"] = len(after)
        out["all_live_at_end"] = bool(after) and len(after[-1][2]) == n
    for when, links in team.links.items():
        out[f"links_{when}"] = {str(k): sum(1 for v in links.values() if v == k)
                                for k in [*range(team.k), None]}
    moved = [rid for rid in killed if team.links.get("before_restart", {}).get(rid)
             not in (None, team.kill)]
    out["killed_router_robots_moved"] = len(moved)
    last = {}
    for row in seen.states:
        last[row[2]] = row
    tiled = len(last) == n and all(
        last[i][5] == (i - 1 if i > 0 else -1) and last[i][6] == (i + 1 if i + 1 < n else -1)
        and (i + 1 == n or abs(last[i][4] - last[i + 1][3]) < GAP_M) for i in range(n))
    out["tiled_at_end"] = bool(tiled)
    if team.kill_wall is not None:  # states naming a neighbour past a live robot
        out["states_skipping_a_neighbour"] = sum(
            1 for row in seen.states if row[0] >= team.kill_wall
            and (row[5] not in (row[2] - 1, -1) or row[6] not in (row[2] + 1, -1)))
    return out


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    why = netns.unavailable()
    if why is not None:
        print(f"multirouter: {why}", file=sys.stderr)
        return 2
    if args.routers < 2 or args.robots < args.routers:
        print("multirouter: need at least 2 routers and a robot on each", file=sys.stderr)
        return 2
    if not 0 < args.kill_at < args.restart_at < args.duration:
        print("multirouter: need 0 < --kill-at < --restart-at < --duration", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)

    def on_term(*_: Any) -> None:  # end what it started and remove the namespaces
        raise SystemExit(1)

    signal.signal(signal.SIGTERM, on_term)
    team = MeshTeam(args)
    began = time.monotonic()
    try:
        team.start()
        code = team.run()
    finally:
        team.close()
        if team.seen is not None:
            (args.out / "seen.json").write_text(json.dumps(
                {"kill_wall": team.kill_wall, "restart_wall": team.restart_wall,
                 "ticks": team.seen.ticks, "states": team.seen.states}))
    if code != 0:
        print(f"multirouter: the world exited with {code}; see {args.out / 'logs'}",
              file=sys.stderr)
        return 1
    m = measures(team)
    m["wall_s"] = round(time.monotonic() - began, 1)
    (args.out / "measured.json").write_text(json.dumps(m, indent=1))
    print(json.dumps(m, indent=1))
    return 0 if m.get("tiled_at_end") and math.isfinite(m["phase_last_quarter_rad"]) else 1


if __name__ == "__main__":
    sys.exit(main())

"""The team across 'hosts': Linux network namespaces, one per robot computer and one
for the base station (router, world, recorder), each robot linked to the base station
through the link emulator, every process using the configuration ``btrack deploy``
renders (TLS, mutual TLS, access control, 1 s lease).

Two teams run side by side, in wall-clock time (``--realtime``, as on real robots;
lockstep would hide the network's delay by waiting for it): one on a clean network,
one with 50 ms delay and 5 % loss each way on every robot link. Each converges (phase
balance, robot 1 started 72 degrees ahead; measured from the recording), then robot
1's link is cut: its neighbours must drop it and meet over its segment within the
lease plus a margin; the link comes back: robot 1 must rejoin between them.

Skipped, with the reason, where namespaces cannot be made (not root).
"""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from deploy.certs import make_cert, make_fleet_certs
from deploy.fleet import Fleet, parse
from deploy.render import client_config, router_config
from tests import netns
from tests.procutil import unique_ns

REASON = netns.unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

ROBOTS = 3
PORT = 7447
LEASE_S = 1.0
CUT_AT_S, REJOIN_AT_S, DURATION_S = 85.0, 95.0, 112.0  # simulated (= wall) time
DELAY_MS, LOSS = 50.0, 0.05
# Phase balance on bare ice converges within a patrol cycle, so a run fits the test's
# time; an 80 s cycle and at least 4 passes per sweep (the team makes 7 on its 2 m
# segments: agent.team keeps passes within 0.3 m; the team converges in 38-48 s)
# leave the robots room to catch up. In
# wall-clock time the world does not wait, so neither do the agents: each uses its
# neighbours' latest states (waiting for the previous tick's, as in lockstep, stalls
# the agents once the robot-to-robot latency nears the 0.1 s tick).
AGENT_ARGS = ["--cycle-s", "80", "--passes", "4", "--neighbour-timeout", "0"]
WORLD_ARGS = ["--map", "no-algae", "--start", "ahead:1", "--seed", "3", "--realtime",
              "--duration", str(DURATION_S), "--wait-recorder", "--startup-timeout", "90"]
MARGIN_S = 2.0  # on top of the lease, for a cut to be noticed
# and for the neighbours to act on it: each first subscribes to its new neighbour's
# state and hears it (about 0.1-0.5 s here; up to 4 s seen on a machine loaded 20x over)
TAKE_MARGIN_S = 6.0
REJOIN_BOUND_S = 14.0  # rejoins take 2-2.5 s; the run ends 17 s after the link returns


class Team:
    def __init__(self, name: str, tmp: Path, impaired: bool):
        self.name, self.impaired = name, impaired
        self.dir = tmp / name
        self.site = netns.Site(ROBOTS, self.dir / "logs")
        self.ns = unique_ns()
        self.seen: netns.Observer | None = None
        self.procs: dict[str, object] = {}
        self.cut_wall: float | None = None
        self.rejoin_wall: float | None = None
        self.cut_t: float | None = None

    def fleet(self) -> Fleet:
        robots = "".join(f'[[robots]]\nid = {i}\nhost = "robot{i}"\n' for i in range(ROBOTS))
        return parse(f'namespace = "{self.ns}"\nlease_s = {LEASE_S}\n[base]\n'
                     f'host = "base"\naddress = "{self.site.base_addr}"\nport = {PORT}\n'
                     f'[tls]\ndir = "{self.dir / "tls"}"\n{robots}')

    def write(self, name: str, conf: dict) -> str:
        path = self.dir / f"{name}.json5"
        path.write_text(json.dumps(conf, indent=1))
        return str(path)

    def start(self) -> None:
        site = self.site
        site.up()
        if self.impaired:
            site.impair(DELAY_MS, LOSS)
        fleet = self.fleet()
        tls = self.dir / "tls"
        make_fleet_certs(fleet, tls, flat=True)
        # the base station's certificate also names the operator's side of it
        make_cert((tls / "ca" / "ca.pem", tls / "ca" / "ca.key"), tls / "base.pem",
                  tls / "base.key", Fleet.common_name(None),
                  (site.base_addr, site.mgmt_addr, "localhost", "127.0.0.1"))
        router = self.write("router", router_config(fleet))
        world, recorder = (self.write(role, client_config(fleet, role))
                           for role in ("world", "recorder"))
        b = site.base_ns
        self.procs["router"] = site.start(b, "router", ["router", "--zenoh-config", router])
        # the operator's laptop hears what the recorder does (and may put nothing)
        self.seen = netns.Observer(client_config(fleet, "recorder", host=site.mgmt_addr),
                                   self.ns)
        common = ["--ns", self.ns]
        self.procs["recorder"] = site.start(b, "recorder", ["record", "--out", str(self.dir),
                                                            "--zenoh-config", recorder,
                                                            *common])
        for i in range(ROBOTS):
            conf = self.write(f"agent{i}", client_config(fleet, fleet.robot(i),
                                                         host=site.base_addr))
            self.procs[f"agent{i}"] = site.start(
                site.robot_ns[i], f"agent{i}",
                ["agent", "--id", str(i), "--robots", str(ROBOTS), *AGENT_ARGS,
                 "--zenoh-config", conf, *common])
        self.procs["world"] = site.start(b, "world", ["world", "--robots", str(ROBOTS),
                                                      *WORLD_ARGS, "--zenoh-config", world,
                                                      *common])

    def step(self) -> None:
        """Cut robot 1's link, then restore it, at the scheduled simulated times."""
        assert self.seen is not None
        t = self.seen.last_t()
        if self.cut_wall is None and t >= CUT_AT_S:
            self.site.link(1, up=False)
            self.cut_wall, self.cut_t = time.monotonic(), t
        elif self.cut_wall is not None and self.rejoin_wall is None and t >= REJOIN_AT_S:
            self.site.link(1, up=True)
            self.rejoin_wall = time.monotonic()

    def logs_of_ended(self) -> str:
        """The last lines of the world's log and of every process that has ended."""
        names = ["world"] + [n for n, p in self.procs.items()
                             if n != "world" and p.poll() is not None]  # type: ignore[attr-defined]
        return "\n".join(f"{n}: " + (self.site.logs / f"{n}.log").read_text()[-1500:]
                         for n in names if (self.site.logs / f"{n}.log").exists())

    def world_running(self) -> bool:
        return self.procs["world"].poll() is None  # type: ignore[attr-defined]

    def close(self) -> None:
        if self.seen is not None:
            (self.dir / "seen.json").write_text(json.dumps(
                {"cut_wall": self.cut_wall, "rejoin_wall": self.rejoin_wall,
                 "ticks": self.seen.ticks, "states": self.seen.states}))
        rec = self.procs.get("recorder")
        if rec is not None:
            try:
                rec.wait(20)  # type: ignore[attr-defined]
            except Exception:
                pass
        if self.seen is not None:
            self.seen.close()
        self.site.close()  # ends every process it started, by pid


class Background:
    """Both teams' whole runs (about two minutes of wall time, nearly all of it waiting on
    the wall clock) in a thread: tests/conftest.py starts it at the session's first test,
    so that the rest of the suite runs meanwhile, and ``teams`` waits for its end."""

    def __init__(self, tmp: Path) -> None:
        self.both = [Team("clean", tmp, impaired=False), Team("impaired", tmp, impaired=True)]
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="netns-teams", daemon=True)

    def start(self) -> Background:
        self.thread.start()
        return self

    def _run(self) -> None:
        both = self.both
        try:
            for team in both:
                team.start()
            deadline = time.monotonic() + DURATION_S + 120
            while any(t.world_running() for t in both):
                assert time.monotonic() < deadline, "the runs did not finish"
                for team in both:
                    team.step()
                time.sleep(0.02)
            for team in both:
                code = team.procs["world"].returncode  # type: ignore[attr-defined]
                assert code == 0, (team.name, team.logs_of_ended())
        except BaseException as exc:  # handed to the tests, which fail on it
            self.error = exc
        finally:
            for team in both:
                team.close()

    def result(self) -> dict[str, Team]:
        self.thread.join(DURATION_S + 300)
        assert not self.thread.is_alive(), "the cross-host runs did not end"
        if self.error is not None:
            raise self.error
        return {t.name: t for t in self.both}


@pytest.fixture(scope="module")
def teams(netns_teams_in_background, tmp_path_factory):
    background = netns_teams_in_background or Background(
        tmp_path_factory.mktemp("netns")).start()
    return background.result()


# The phase moves one pass at a time (agent.phase): with 7 passes a step is 0.45 rad,
# and on the impaired link robots step up to a few
# ticks apart, so the smoothed worst pair settles at 0.05-0.22 rad (measured over seven
# runs) where the clean team's settles at 0.05-0.07. The impaired team must converge
# to within half a step; the clean one to the report's band.
IMPAIRED_PHASE_BAND_RAD = 0.3


def _pre_cut_convergence(team: Team) -> dict[str, float]:
    from report.load import load_run
    from report.measures import converge_time, max_over_pairs, running_mean
    from report.series import error_series
    from report.summary import CONVERGE_SMOOTH_S, PHASE_BAND_RAD

    s = error_series(load_run(team.dir / "run.mcap"))
    assert team.cut_t is not None
    keep = s.t < team.cut_t
    t, phase = s.t[keep], s.phase[:, keep]
    smooth = running_mean(t, max_over_pairs(phase), CONVERGE_SMOOTH_S)
    first = np.nanmean(np.abs(phase[:, t < 10.0]))
    last = np.nanmean(np.abs(phase[:, t > team.cut_t - 10.0]))
    band = IMPAIRED_PHASE_BAND_RAD if team.impaired else PHASE_BAND_RAD
    return {"converge_s": float(converge_time(t, phase, band, CONVERGE_SMOOTH_S)),
            "phase_first_10s_rad": float(first), "phase_last_10s_rad": float(last),
            "smoothed_max_at_cut_rad": float(smooth[-1]), "band_rad": band}


def _agent_rate(team: Team) -> float:
    """States per second per agent before the cut (the world ticks at 10 Hz)."""
    assert team.cut_t is not None
    n = sum(1 for r in team.seen.states if r[1] < team.cut_t)
    return round(n / ROBOTS / team.cut_t, 2)


def _gap_closed(states, since: float) -> float | None:
    """Wall seconds from ``since`` until robots 0 and 2 are each other's neighbours and
    their latest boundaries meet (robot 1's segment shared out between them)."""
    latest: dict[int, tuple] = {}
    for row in states:
        latest[row[2]] = row
        if row[0] < since or 0 not in latest or 2 not in latest:
            continue
        a, b = latest[0], latest[2]
        if a[6] == 2 and b[5] == 0 and abs(a[4] - b[3]) < 0.05:
            return row[0] - since
    return None


def _first(rows, since: float, cond) -> float | None:
    for row in rows:
        if row[0] >= since and cond(row):
            return row[0] - since
    return None


def _report(team: Team, **numbers: object) -> None:
    path = team.dir.parent / "measured.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    data.setdefault(team.name, {}).update(numbers)
    path.write_text(json.dumps(data, indent=1))
    print(f"\n{team.name}: {numbers}")


@pytest.mark.parametrize("name", ["clean", "impaired"])
def test_team_balances_across_hosts(teams, name: str) -> None:
    team = teams[name]
    assert team.seen.ticks and team.cut_t is not None, "the world never reached the cut"
    m = _pre_cut_convergence(team)
    # a robot dropped before the cut (its lease ran out on a stalled link) is a fact
    # to know about the network, not a failure of the team; it shows in the numbers
    drops = sum(1 for a, b in zip(team.seen.ticks, team.seen.ticks[1:], strict=False)
                if b[1] < team.cut_t and len(b[2]) < len(a[2]))
    _report(team, **m, robots_dropped_before_cut=drops,
            agent_ticks_per_s=_agent_rate(team))
    assert math.isfinite(m["converge_s"]), m
    assert m["converge_s"] < CUT_AT_S - 10, m
    # and it stays there: the last 10 s before the cut inside the band too (not "a third
    # of the first 10 s": a start whose first 10 s happened to be near 0.2 rad failed it)
    assert m["phase_last_10s_rad"] < m["band_rad"], m


@pytest.mark.parametrize("name", ["clean", "impaired"])
def test_cut_link_neighbours_take_its_segment_within_the_lease(teams, name: str) -> None:
    team = teams[name]
    assert team.cut_wall is not None
    cut = team.cut_wall
    dropped = _first(team.seen.ticks, cut, lambda r: 1 not in r[2])
    before = [r for r in team.seen.states if r[0] < cut]
    hi0 = next(r[4] for r in reversed(before) if r[2] == 0)
    lo2 = next(r[3] for r in reversed(before) if r[2] == 2)
    # each moves its boundary into the gap (staggered in wall-clock time, they need not
    # agree at once: they close on a point between the two old boundaries)
    took0 = _first(team.seen.states, cut, lambda r: r[2] == 0 and r[6] == 2
                   and r[4] > hi0 + 0.1 * (lo2 - hi0))
    took2 = _first(team.seen.states, cut, lambda r: r[2] == 2 and r[5] == 0
                   and r[3] < lo2 - 0.1 * (lo2 - hi0))
    closed = _gap_closed(team.seen.states, cut)
    _report(team, cut_detected_by_world_s=dropped, robot0_took_s=took0, robot2_took_s=took2,
            gap_closed_s=closed, gap_m=lo2 - hi0)
    assert dropped is not None and dropped <= LEASE_S + MARGIN_S, dropped
    for took in (took0, took2, closed):
        assert took is not None and took <= LEASE_S + TAKE_MARGIN_S, (took0, took2, closed)
    # they meet: one boundary between robots 0 and 2 where robot 1's segment was
    assert team.rejoin_wall is not None
    during = [r for r in team.seen.states if cut + closed < r[0] < team.rejoin_wall]
    last0 = next(r for r in reversed(during) if r[2] == 0)
    last2 = next(r for r in reversed(during) if r[2] == 2)
    assert abs(last0[4] - last2[3]) < 0.05 and last0[6] == 2 and last2[5] == 0, (last0, last2)


@pytest.mark.parametrize("name", ["clean", "impaired"])
def test_robot_rejoins_when_its_link_returns(teams, name: str) -> None:
    team = teams[name]
    assert team.rejoin_wall is not None
    back = team.rejoin_wall
    live = _first(team.seen.ticks, back, lambda r: 1 in r[2])
    n0 = _first(team.seen.states, back, lambda r: r[2] == 0 and r[6] == 1)
    n2 = _first(team.seen.states, back, lambda r: r[2] == 2 and r[5] == 1)
    _report(team, rejoin_live_s=live, rejoin_robot0_s=n0, rejoin_robot2_s=n2)
    assert live is not None and live <= REJOIN_BOUND_S, live
    assert n0 is not None and n2 is not None and max(n0, n2) <= REJOIN_BOUND_S, (n0, n2)
    # at the end the three segments tile the edge again, in order
    last = {rid: next(r for r in reversed(team.seen.states) if r[2] == rid)
            for rid in range(ROBOTS)}
    assert last[0][6] == 1 and last[1][5] == 0 and last[1][6] == 2 and last[2][5] == 1, last
    assert abs(last[0][4] - last[1][3]) < 0.05 and abs(last[1][4] - last[2][3]) < 0.05, last
    assert last[0][4] < last[1][4], last

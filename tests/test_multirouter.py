"""A team behind a mesh of three Zenoh routers on three 'hosts' (network namespaces),
mutual TLS and access control on every router, and one router killed and restarted
mid-run: ``bench/multirouter.py`` run as a user would, judged on what it measured.

Six robots, robot i behind router i mod 3, so every robot's neighbours are behind the
other two routers and every state crosses the mesh; the world paces on the wall clock.
Router 2 is killed (SIGKILL) at 25 s and started again at 40 s; in a second run it
hangs instead (SIGSTOP: its links open and silent, as a host that froze) and goes on
at 40 s. Its two robots must move to another router (each lists the others after its
own) without the team losing them for more than a lease (a hung router: a lease, then
the opening's timeout on it, before the next router is tried), and no stretch of the
edge may go without an owner longer than that. Skipped, with the reason, where
namespaces cannot be made (not root).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from deploy.render import open_timeout_ms
from tests import netns
from tests.procutil import end

REASON = netns.unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

BENCH = Path(__file__).resolve().parents[1] / "bench" / "multirouter.py"
LEASE_S, MARGIN_S = 1.0, 2.0
ROBOTS, ROUTERS = 6, 3


# what a robot of a hung router waits before it tries the next (deploy.render)
OPEN_S = open_timeout_ms(LEASE_S) / 1000


@pytest.fixture(scope="module", params=["kill", "freeze"])
def measured(request, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp(f"mesh-{request.param}")
    proc = subprocess.Popen([sys.executable, str(BENCH), "--robots", str(ROBOTS), "--routers",
                             str(ROUTERS), "--realtime", "--duration", "60", "--kill-at", "25",
                             "--restart-at", "40", "--lease", str(LEASE_S), "--out", str(out),
                             "--fault", request.param],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        log, _ = proc.communicate(timeout=300)
    finally:
        end(proc, grace_s=60)  # it ends its own processes and namespaces on SIGTERM
    path = out / "measured.json"
    assert proc.returncode == 0 and path.exists(), log[-3000:]
    return json.loads(path.read_text())


def test_every_router_carries_robots_and_the_team_is_balanced(measured) -> None:
    assert measured["links_before_kill"] == {"0": 2, "1": 2, "2": 2, "None": 0}, measured
    if measured["fault"] == "kill":
        assert measured["phase_last_quarter_rad"] < 0.05, measured
    else:  # its robots were lost to the team for 3 s, 20 s before the last quarter began
        # (measured 0.054 against 0.033 in the 10 s before the hang)
        assert measured["phase_last_quarter_rad"] < min(
            0.1, 2 * measured["phase_before_kill_rad"]), measured
    assert measured["tiled_at_end"] and measured["all_live_at_end"], measured


def test_a_killed_routers_robots_move_to_another_within_a_lease(measured) -> None:
    assert measured["killed_router"] == 2 and measured["robots_on_killed_router"] == 2
    # both robots of router 2 hold a link to another router while it is down
    assert measured["killed_router_robots_moved"] == 2, measured
    assert measured["links_before_restart"]["2"] == 0, measured
    assert measured["links_before_restart"]["None"] == 0, measured
    # a hung router is found out by the lease, and its half-open handshake then holds a
    # robot for the opening's timeout (Zenoh's own default of 10 s: 11.1 s measured)
    hung = OPEN_S if measured["fault"] == "freeze" else 0.0
    assert measured["silence_max_s"] <= LEASE_S + hung + MARGIN_S, measured
    assert measured["unowned_max_s"] <= LEASE_S + MARGIN_S, measured
    # (a killed router's robots are back so soon that the world may never drop them)
    if measured["detected_s"] is not None:
        assert measured["detected_s"] <= LEASE_S + MARGIN_S, measured


def test_the_team_runs_on_after_the_router_returns(measured) -> None:
    # the world ticked on for the last 20 s with every robot live
    assert measured["ticks_after_restart"] >= 150, measured
    assert measured["ticks_seen"] == 600, measured

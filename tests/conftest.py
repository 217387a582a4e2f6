"""Fixtures more than one test module uses."""

from __future__ import annotations

import os

import pytest

from tests.procutil import run_sim


@pytest.fixture(scope="session", autouse=True)
def netns_teams_in_background(request, tmp_path_factory):
    """The cross-host teams of tests/test_netns.py, started at the session's first test
    when any of that file's tests is to run (and network namespaces are here): their two
    minutes on the wall clock pass while the rest of the suite runs. Each ends every
    process it started, by pid, however the tests go.

    Not under pytest-xdist: every worker collects every test, so each would start its
    own pair of teams; there the worker given test_netns.py starts them (its ``teams``
    fixture), while the other worker runs the rest of the suite."""
    if os.environ.get("PYTEST_XDIST_WORKER") or not any(
            item.path.name == "test_netns.py" for item in request.session.items):
        yield None
        return
    from tests import test_netns

    if test_netns.REASON is not None:
        yield None
        return
    background = test_netns.Background(tmp_path_factory.mktemp("netns")).start()
    yield background
    background.thread.join(test_netns.DURATION_S + 300)


@pytest.fixture(scope="session")
def pf_run(tmp_path_factory):
    """A short particle-filter run with a row of two scanners and the particle clouds
    sampled every 5 ticks, its recording given the
    Foxglove channels by ``btrack sim`` at its end (tests/test_foxglove.py reads them,
    tests/test_replay.py replays it)."""
    out = tmp_path_factory.mktemp("fox") / "pf"
    result = run_sim(out, "--robots", "2", "--duration", "20", "--scanners", "2",
                     "--clouds-every", "5", "--seed", "3", timeout=240, scene=True)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Foxglove channels added" in result.stdout, result.stdout[-2000:]
    return out

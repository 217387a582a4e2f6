"""Fixtures more than one test module uses."""

from __future__ import annotations

import pytest

from tests.procutil import run_sim


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

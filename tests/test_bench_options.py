"""The issue 21 benches refuse bad options by name before they start a process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench"


@pytest.mark.parametrize(("bench", "args", "why"), [
    ("lockstep.py", ["--robots", "0"], "at least 1"),
    ("lockstep.py", ["--robots", "101"], "at most 100"),
    ("lockstep.py", ["--duration", "nan"], "above 0"),
    ("lockstep.py", ["--repeat", "0"], "at least 1"),
    ("tick_cpu.py", ["--duration", "-5"], "above 0"),
    ("tick_cpu.py", ["--env", "NOEQUALS"], "NAME=VALUE"),
    ("soak.py", ["--hours", "0"], "must be positive"),
    ("soak.py", ["--robots", "1"], "at least 2"),
])
def test_a_bad_option_is_refused(bench, args, why):
    res = subprocess.run([sys.executable, str(BENCH / bench), *args], capture_output=True,
                         text=True, timeout=30)
    assert res.returncode == 2
    assert why in res.stderr


def test_soak_puts_readings_on_simulated_time_and_averages_by_hour():
    sys.path.insert(0, str(BENCH))
    import numpy as np
    import soak

    assert soak.process_name(["/x/.venv/bin/python", "/x/.venv/bin/btrack", "agent", "--id",
                              "2", "--robots", "3"]) == "agent 2"
    assert soak.process_name(["/x/bin/btrack", "record", "--out", "d"]) == "recorder"
    assert soak.process_name(["/x/bin/btrack", "sim"]) == "launcher"
    assert soak.process_name(["sleep", "1"]) == "other"
    # ticks at 0, 10, 20 s of simulated time stamped 1, 2, 3 s of wall time
    sim = soak.wall_to_sim(np.array([0, 1_500_000_000, 5_000_000_000]),
                           np.array([1_000_000_000, 2_000_000_000, 3_000_000_000]),
                           np.array([0.0, 10.0, 20.0]))
    assert np.isnan(sim[0]) and sim[1] == 5.0 and sim[2] == 20.0
    t = np.array([10.0, 3000.0, 3700.0, 7000.0])
    err = np.array([[1.0, -3.0, np.nan, 0.5], [np.nan, 1.0, 2.0, np.nan]])
    assert soak.hourly_means(t, err, 3)[:2] == [5.0 / 3.0, 1.25]
    assert np.isnan(soak.hourly_means(t, err, 3)[2])
    readings = [{"name": "world", "sim_t": 100.0, "rss_mb": 80.0},
                {"name": "world", "sim_t": 4000.0, "rss_mb": 90.0},
                {"name": "agent 0", "sim_t": float("nan"), "rss_mb": 30.0}]
    assert soak.memory_at(readings, 3600.0) == {"world": 80.0}

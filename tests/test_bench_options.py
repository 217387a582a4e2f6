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
    ("soak.py", ["--wall-limit", "0"], "must be positive"),
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


def test_soak_reads_the_recorders_lag_from_the_recording(tmp_path):
    # the world stamps tick k at 1 + 0.01 k s; the recorder takes it 0.5 s later, then
    # falls behind by 20 ms more a tick: the lag is read back from the MCAP file
    sys.path.insert(0, str(BENCH))
    import numpy as np
    import soak

    from recorder.writer import Recording, RunWriter
    from report.load import load_run
    from wire import Tick, encode

    writer = RunWriter(tmp_path / "run.mcap")
    rec = Recording(writer)
    sent = [10**18 + k * 10**7 for k in range(41)]
    for k in range(41):
        tick = Tick(t=k * 0.1, k=k, live=[0], done=k == 40, wall_ns=sent[k])
        rec.handle("world/tick", encode(tick), sent[k] + 5 * 10**8 + k * 2 * 10**7)
    writer.close()
    run = load_run(tmp_path / "run.mcap")
    assert run.tick_recorded_ns.tolist() == [s + 5 * 10**8 + k * 2 * 10**7
                                             for k, s in enumerate(sent)]
    lag = soak.recorder_lag(run)
    assert np.allclose(lag, 0.5 + 0.02 * np.arange(41))
    by_hour = soak.hourly_lag(run.tick_t, lag, 2)
    assert by_hour[0]["median_s"] == pytest.approx(0.9)
    assert by_hour[0]["max_s"] == pytest.approx(1.3)
    assert np.isnan(by_hour[1]["median_s"])

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
])
def test_a_bad_option_is_refused(bench, args, why):
    res = subprocess.run([sys.executable, str(BENCH / bench), *args], capture_output=True,
                         text=True, timeout=30)
    assert res.returncode == 2
    assert why in res.stderr

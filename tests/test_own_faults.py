"""The launcher's word on agents' own faults, read from real processes' closing lines."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from deploy.procs import Child, own_faults


def closed_with(tmp_path: Path, name: str, counts: dict[str, int]) -> Child:
    """A real process that ends as a btrack process does: its counts as its last line."""
    out, log = tmp_path / f"{name}.out", tmp_path / f"{name}.log"
    with open(out, "wb") as stdout:
        script = f"print('tick'); print({json.dumps(json.dumps(counts))})"
        proc = subprocess.Popen([sys.executable, "-c", script], stdout=stdout,
                                stderr=subprocess.DEVNULL)
        proc.wait(30)
    return Child(name, proc, log, out)


def test_agents_with_faults_of_their_own_are_named_with_their_logs(tmp_path: Path) -> None:
    calm = closed_with(tmp_path, "agent0", {"agent": 0, "ticks": 9, "faults": 0})
    faulty = closed_with(tmp_path, "agent1.1", {"agent": 1, "ticks": 8, "faults": 2})
    world = closed_with(tmp_path, "world", {"ticks": 9, "faults": 5})  # not an agent's count
    assert own_faults([calm, world]) is None
    line = own_faults([calm, faulty, world])
    assert line is not None
    assert "agent1.1 2" in line and str(faulty.log_path) in line
    assert "agent0" not in line and "world" not in line

"""``btrack record`` as a real process on a private namespace: it records what crosses
the bus, stores garbage as an invalid record, and stops by itself on the final tick."""

from __future__ import annotations

import dataclasses
import json
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import zenoh
from mcap.reader import make_reader

from tests.procutil import end, free_port, taken_port, unique_ns
from wire import AgentState, Keys, Progress, Tick, Truth, WorldInfo, decode, encode
from wire.session import SessionOptions, open_session


@contextmanager
def recorder_on_bus(out: Path) -> Iterator[tuple[subprocess.Popen[bytes], Keys, zenoh.Session]]:
    """A real recorder writing OUT/run.mcap on a private namespace, and a test session
    on its bus once the recorder is alive; the recorder is ended whatever happens."""
    ns, port = unique_ns(), free_port()
    keys = Keys(ns)
    proc = start_recorder(out, ns, port)
    try:
        with bus_session(ns, port) as session:
            wait_recorder_alive(session, keys, proc)
            yield proc, keys, session
    finally:
        end(proc)


def start_recorder(out: Path, ns: str, port: int) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "btrack",
            "record",
            "--out",
            str(out),
            "--ns",
            ns,
            "--no-multicast",
            "--listen",
            f"tcp/127.0.0.1:{port}",
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )


def bus_session(ns: str, port: int) -> zenoh.Session:
    return open_session(
        SessionOptions(ns=ns, mode="peer", connect=(f"tcp/127.0.0.1:{port}",), multicast=False)
    )


def wait_recorder_alive(session: zenoh.Session, keys: Keys,
                        proc: subprocess.Popen[bytes] | None = None,
                        timeout: float = 30.0) -> None:
    """Until the recorder's liveliness token is seen; a recorder that died meanwhile
    fails the wait at once, with what it said."""
    seen = threading.Event()
    sub = session.liveliness().declare_subscriber(
        keys.alive_recorder(),
        lambda s: seen.set() if s.kind == zenoh.SampleKind.PUT else None,
        history=True,
    )
    try:
        deadline = time.monotonic() + timeout
        while not seen.wait(0.2):
            if proc is not None and proc.poll() is not None:
                said = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
                raise AssertionError(f"the recorder exited ({proc.returncode}): {said}")
            assert time.monotonic() < deadline, "the recorder's liveliness token never appeared"
    finally:
        sub.undeclare()


def ask_progress(session: zenoh.Session, keys: Keys,
                 until: Callable[[Progress], bool], timeout: float = 20.0) -> Progress:
    """Query the recorder's progress until an answer satisfies ``until``."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        for reply in session.get(keys.progress(), timeout=2.0):
            assert reply.ok is not None, reply.err
            last = decode(Progress, reply.ok.payload.to_bytes())
            if until(last):
                return last
        time.sleep(0.05)
    raise AssertionError(f"no progress answer as wanted; the last: {last}")


def read_topics(path: Path) -> tuple[Counter[str], dict[str, list[dict]]]:
    counts: Counter[str] = Counter()
    data: dict[str, list[dict]] = {}
    with open(path, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            counts[channel.topic] += 1
            data.setdefault(channel.topic, []).append(json.loads(message.data))
            assert channel.message_encoding == "json"
            assert schema is not None and schema.encoding == "jsonschema"
    return counts, data


def state(k: int) -> AgentState:
    return AgentState(
        t=k * 0.1,
        k=k,
        robot=0,
        lo=0.0,
        hi=2.0,
        phase=0.5,
        phase_des=0.5,
        workload=0.6,
        depth_avg=0.3,
        direction=1,
        lower=-1,
        upper=1,
        edge_lo=0.0,
        edge_hi=6.0,
    )


def ten_seconds(robots: int) -> WorldInfo:
    """The world of a ten-second run of ``robots`` on a 6 m edge."""
    return WorldInfo(map="no-algae", start="in-phase", robots=robots, localization="truth",
                     seed=1, duration_s=10.0, dt=0.1, edge_lo=0.0, edge_hi=6.0, bin_m=0.1,
                     patrol_depth=[0.3] * 60, robot_radius=0.17, min_depth=0.3,
                     margin_out=0.3)


def test_progress_gives_the_agents_newest_common_tick_when_the_worlds_lag(
        tmp_path: Path) -> None:
    """Under load the recorder hears the agents' states far ahead of the world's ticks
    (the world's one link falls behind the agents' many): progress then gives the
    phases of the newest tick every robot still publishing has a state of, and its time,
    not nothing. A robot whose states stopped is left out."""
    with recorder_on_bus(tmp_path) as (_, keys, session):
        session.put(keys.world_info(), encode(ten_seconds(robots=3)))
        session.put(keys.world_tick(), encode(Tick(0.0, 0, [0, 1, 2])))
        for k in range(31):
            for robot in (0, 1, 2) if k <= 10 else (0, 1):  # robot 2 stops at tick 10
                if robot == 1 and k == 30:
                    continue  # robot 1's state of tick 30 is not in yet
                session.put(keys.state(robot), encode(dataclasses.replace(
                    state(k), robot=robot, phase=0.1 * robot + 0.01 * k)))
        session.put(keys.world_tick(), encode(Tick(0.1, 1, [0, 1, 2])))
        progress = ask_progress(session, keys, lambda p: p.k == 1)
        assert progress.t == pytest.approx(0.1) and progress.live == [0, 1, 2]
        assert progress.robots == [0, 1] and progress.states_t == pytest.approx(2.9)
        assert progress.phase == pytest.approx([0.29, 0.39])
        # a state of robot 0 forged for a tick far ahead (inside the recorder's window):
        # the others are not taken for stopped, and the forgery is not the picture
        session.put(keys.state(0), encode(dataclasses.replace(state(500), phase=3.0)))
        session.put(keys.world_tick(), encode(Tick(0.2, 2, [0, 1, 2])))
        progress = ask_progress(session, keys, lambda p: p.k == 2)
        assert progress.robots == [0, 1] and progress.states_t == pytest.approx(2.9)
        assert progress.phase == pytest.approx([0.29, 0.39])
        session.put(keys.world_tick(), encode(Tick(9.9, 99, [0, 1], done=True)))


def test_recorder_records_and_stops_on_final_tick(tmp_path: Path) -> None:
    with recorder_on_bus(tmp_path) as (proc, keys, session):
        token = session.liveliness().declare_token(keys.alive(0))
        info = WorldInfo(
            map="no-algae",
            start="in-phase",
            robots=1,
            localization="truth",
            seed=1,
            duration_s=0.4,
            dt=0.1,
            edge_lo=0.0,
            edge_hi=6.0,
            bin_m=0.1,
            patrol_depth=[0.3] * 60,
            robot_radius=0.17,
            min_depth=0.3,
            margin_out=0.3,
        )
        session.put(keys.world_info(), encode(info))
        for k in range(3):
            session.put(keys.truth(), encode(Truth(k * 0.1, k, [0], [1.0], [-1.0], [0.0])))
            session.put(keys.state(0), encode(state(k)))
            session.put(keys.world_tick(), encode(Tick(k * 0.1, k, [0])))
        # asked how far the run has got, it answers from what it recorded
        progress = ask_progress(session, keys, lambda p: p.k == 2)
        assert (progress.t, progress.live, progress.done) == (0.2, [0], False)
        assert (progress.robots, progress.phase, progress.workload) == ([0], [0.5], [0.6])
        assert progress.states_t == pytest.approx(0.2)
        session.put(keys.state(0), b"\x93\x01\x02")  # a msgpack list, not a state
        session.put(keys.world_tick(), encode(Tick(0.3, 3, [0], done=True)))
        out, err = proc.communicate(timeout=30)
        token.undeclare()
    assert proc.returncode == 0, err.decode()
    summary = json.loads(out.decode().strip().splitlines()[-1])
    assert summary == {"messages": 12, "invalid": 1, "rejected": 0, "done": True,
                       "ticks": 4, "lost_ticks": 0, "last_k": 3}
    counts, data = read_topics(tmp_path / "run.mcap")
    assert counts["world/info"] == 1
    assert counts["world/truth"] == 3
    assert data["world/truth"][1] == {"t": 0.1, "k": 1, "robots": [0], "x": [1.0],
                                      "y": [-1.0], "theta": [0.0]}
    assert counts["agent/0/state"] == 3
    assert counts["world/tick"] == 4
    assert counts["invalid/agent/0/state"] == 1
    assert data["invalid/agent/0/state"][0]["hex"] == "93 01 02".replace(" ", "")
    assert data["alive/agent/0"] == [{"alive": True}]
    assert data["world/tick"][-1]["done"] is True
    assert data["agent/0/state"][2]["k"] == 2


def test_a_lost_tick_is_gone_past_and_forged_ones_are_refused(tmp_path: Path) -> None:
    """A tick lost on the way (tick 10 never sent) once had the recorder refuse every later
    tick as "not the next". Now a tick that skips ahead is kept when its own next comes,
    and refused when the skipped next comes instead (a forged tick 40 between 14 and 15),
    when it is more than MAX_TICK_GAP ahead, or beyond the run's last tick (a forged first
    tick of 10^6, which once would have set the clock): none can wedge the recording."""
    from wire.tickorder import MAX_TICK_GAP

    with recorder_on_bus(tmp_path) as (proc, keys, session):
        session.put(keys.world_info(), encode(ten_seconds(robots=1)))

        def tick(k: int) -> None:
            session.put(keys.world_tick(), encode(Tick(round(k * 0.1, 9), k, [0], done=k == 99)),
                        congestion_control=zenoh.CongestionControl.BLOCK)

        for k in [10**6, *range(10), *range(11, 15), 40, 14 + MAX_TICK_GAP + 1]:
            tick(k)
        for k in range(15, 100):
            tick(k)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err.decode()
    summary = json.loads(out.decode().strip().splitlines()[-1])
    assert (summary["done"], summary["ticks"], summary["lost_ticks"]) == (True, 99, 1)
    assert summary["rejected"] == 3
    counts, data = read_topics(tmp_path / "run.mcap")
    assert [t["k"] for t in data["world/tick"]] == [k for k in range(100) if k != 10]
    assert counts["rejected/world/tick"] == 3
    reasons = sorted(r["error"] for r in data["rejected/world/tick"])
    assert reasons == ["tick 1000000 after the run's last tick, 99",
                       "tick 40 after tick 14, and its next never came",
                       f"tick {15 + MAX_TICK_GAP} after tick 14: more than {MAX_TICK_GAP} ahead"]
    done = subprocess.run([sys.executable, "-m", "btrack", "report", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert "99 of the run's 100 ticks recorded" in (tmp_path / "summary.json").read_text(), (
        done.stderr)


def test_a_run_on_its_epochs_tick_grid_is_recorded_to_its_done_tick(tmp_path: Path) -> None:
    """The hardware loop's ticks count from the run's epoch (as its bridges' Sense do),
    so its run begins at the tick its team was up by: ``btrack sim --hil`` recorded 22 of
    its 61 ticks and refused the rest, the done tick with them ("after the run's last
    tick, 59"), and its recorder never ended by itself. WorldInfo says the first tick,
    and the run's last is counted from it."""
    with recorder_on_bus(tmp_path) as (proc, keys, session):
        first = 4321
        info = WorldInfo(map="no-algae", start="in-phase", robots=1, localization="pf",
                         seed=1, duration_s=2.0, dt=0.1, edge_lo=0.0, edge_hi=6.0, bin_m=0.1,
                         patrol_depth=[0.3] * 60, robot_radius=0.17, min_depth=0.3,
                         margin_out=0.3, realtime=True, first_k=first)
        session.put(keys.world_info(), encode(info))
        for k in range(first, first + 20):
            session.put(keys.world_tick(), encode(Tick(round(k * 0.1, 9), k, [0],
                                                       done=k == first + 19)),
                        congestion_control=zenoh.CongestionControl.BLOCK)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err.decode()
    summary = json.loads(out.decode().strip().splitlines()[-1])
    assert (summary["done"], summary["ticks"], summary["rejected"]) == (True, 20, 0), summary
    assert summary["last_k"] == first + 19


def test_recorder_finishes_the_file_on_sigterm(tmp_path: Path) -> None:
    with recorder_on_bus(tmp_path) as (proc, keys, session):
        session.put(keys.world_tick(), encode(Tick(0.0, 0, [])))
        session.put(keys.world_tick(), b"garbage")
        session.put(keys.world_tick(), encode(Tick(0.1, 1, [])))
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err.decode()
    summary = json.loads(out.decode().strip().splitlines()[-1])
    # whatever arrived before the signal is in a finished, readable file
    counts, _ = read_topics(tmp_path / "run.mcap")
    assert counts["world/tick"] == summary["messages"]
    assert counts["invalid/world/tick"] == summary["invalid"]
    assert summary["done"] is False  # stopped before the final tick


def test_a_sigkilled_recorders_file_is_reported_as_cut_short(tmp_path: Path) -> None:
    """Issue 19, item 4: a recorder killed mid-run leaves an MCAP with no summary and half
    a chunk; ``btrack report`` reads what it holds and says it was cut short (it could not
    read such a file at all)."""
    from report.synthetic import synthetic_messages

    with recorder_on_bus(tmp_path) as (proc, keys, session):
        sent_k = 0
        for topic, payload, _ in synthetic_messages(duration_s=300.0):
            # blocking, not dropping: 2000 ticks' messages go out as fast as Python puts
            # them, and ticks dropped on the way would be missing from the count below
            # (a recorder once refused every tick after a lost one: seen in CI)
            session.put(f"{keys.ns}/{topic}", payload,
                        congestion_control=zenoh.CongestionControl.BLOCK)
            if topic == "world/tick":
                sent_k += 1
                if sent_k == 2000:  # of 3000: the run is two thirds through
                    break
        ask_progress(session, keys, lambda p: p.k >= 1999)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    done = subprocess.run([sys.executable, "-m", "btrack", "report", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "the recording is incomplete" in done.stderr and "Traceback" not in done.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["recording_complete"] is False
    assert "no summary (its recorder did not finish it)" in summary["recording_note"]
    assert summary["ticks_expected"] == 3000
    # what was flushed to the file before the kill: whole chunks, most of the run
    assert 500 < summary["ticks"] < 2000
    assert f"{summary['ticks']} of the run's 3000 ticks recorded" in summary["recording_note"]
    assert summary["phase_sse_rad"] is not None
    assert "**This recording is incomplete**" in (tmp_path / "report.md").read_text()


def test_the_launcher_says_what_a_recording_lacks(tmp_path: Path) -> None:
    """Issue 19, item 2: a recorder stopped before the run's last tick left the launcher
    exiting 0. What it checks now, on a real recorder's own count: the ticks it holds of
    the run's, and whether the final one is among them."""
    from deploy.launcher import _recording_missing
    from deploy.procs import ProcessGroup

    ns, port = unique_ns(), free_port()
    keys = Keys(ns)
    group = ProcessGroup(tmp_path / "logs")
    try:
        recorder = group.start("recorder", ["record", "--out", str(tmp_path), "--ns", ns,
                                            "--no-multicast", "--listen",
                                            f"tcp/127.0.0.1:{port}"])
        with bus_session(ns, port) as session:
            wait_recorder_alive(session, keys, recorder.proc)
            for k in range(5):
                session.put(keys.world_tick(), encode(Tick(k * 0.1, k, [])))
            ask_progress(session, keys, lambda p: p.k == 4)
            group.stop(recorder)  # SIGTERM: it finishes its file and gives its count
        for total in (5, 9):
            assert _recording_missing(recorder, total) == (
                f"it holds 5 of the run's {total} ticks, not the final one")
    finally:
        group.stop_all()


def test_a_recorder_whose_endpoint_is_taken_says_so_in_one_line(tmp_path: Path) -> None:
    """A listening endpoint already in use ended the recorder with a Zenoh traceback; it
    is now one line naming the endpoint and the cause, and exit status 1."""
    with taken_port() as port:
        proc = start_recorder(tmp_path, unique_ns(), port)
        try:
            _, err = proc.communicate(timeout=60)
        finally:
            end(proc)
    text = err.decode()
    assert proc.returncode == 1, text
    assert "Traceback" not in text
    line = [ln for ln in text.splitlines() if ln.startswith("btrack record:")]
    assert len(line) == 1, text
    assert f"tcp/127.0.0.1:{port}" in line[0] and "Address already in use" in line[0]
    assert ".rs:" not in line[0]  # Zenoh's source locations are left out

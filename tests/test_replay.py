"""Issue 20, item 3: ``btrack replay`` of a recorded particle-filter run into a fresh
``btrack localizer`` and ``btrack record``, real processes on a private namespace: the
new recording's poses are the original's, and no message was lost."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter, defaultdict

from mcap.reader import make_reader

from deploy.procs import listening
from tests.procutil import end, free_port, member_args, start, unique_ns, wait_for

REPLAYED = ("world/**", "robot/*/sense", "laser/scan")


def _read(path):
    counts: Counter[str] = Counter()
    ticks: dict[str, list[int]] = defaultdict(list)
    poses: dict[tuple[int, int], tuple[float, float, float]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            topic = channel.topic
            if topic.startswith(("/", "alive/")):
                continue
            counts[topic] += 1
            if topic in ("laser/scan", "world/tick") or topic.endswith("/sense"):
                ticks[topic].append(json.loads(message.data)["k"])
            if topic.endswith("/pose"):
                m = json.loads(message.data)
                poses[m["k"], m["robot"]] = (m["x"], m["y"], m["theta"])
    return counts, poses, ticks


def test_a_replayed_pf_run_gives_the_same_poses(pf_run, tmp_path):
    ns, port = unique_ns(), free_port()
    out = tmp_path / "again"
    procs = []
    try:
        recorder = start(["record", "--out", str(out), "--ns", ns, "--mode", "router",
                          "--listen", f"tcp/127.0.0.1:{port}", "--no-multicast", "--drain",
                          "2"], log=tmp_path / "recorder.log")
        procs.append(recorder)
        wait_for(lambda: listening(port), 30, "the recorder's router")
        # as the run's own localizer (btrack sim gives it the run's seed), with room to
        # wait for a robot's sensing: the lockstep never let it go on without one
        procs.append(start(["localizer", "--robots", "2", "--seed", "3", "--sense-timeout",
                            "30", *member_args(ns, port)], log=tmp_path / "localizer.log"))
        replay = subprocess.run(
            [sys.executable, "-m", "btrack", "replay", str(pf_run / "run.mcap"), "--fast",
             "--pace-on", "robot/*/pose", "--topics", *REPLAYED,
             "--wait-for", "alive/localizer", "--wait-for", "alive/recorder",
             # a client of the router: one link, so every listener hears the messages in
             # the order they were put (a peer's direct links come up while it runs)
             "--ns", ns, "--mode", "client", "--connect", f"tcp/127.0.0.1:{port}",
             "--no-multicast"], capture_output=True, text=True, timeout=180)
        assert replay.returncode == 0, replay.stderr[-3000:]
        assert recorder.wait(60) == 0, (tmp_path / "recorder.log").read_text()[-2000:]
    finally:
        for proc in procs:
            end(proc)
    localizer = procs[1].stdout.read().decode() if len(procs) > 1 else ""
    sent = json.loads(replay.stdout.strip().splitlines()[-1])

    before, poses_before, _ = _read(pf_run / "run.mcap")
    after, poses_after, after_ticks = _read(out / "run.mcap")
    replayed = {t for t in before if t.startswith(("world/", "laser/")) or t.endswith("/sense")}
    assert sent["topics"] == {t: before[t] for t in replayed}
    for topic in sorted(replayed) + ["robot/0/pose", "robot/1/pose"]:
        missing = sorted(set(range(200)) - set(after_ticks.get(topic, range(200))))
        assert after[topic] == before[topic], (topic, after[topic], before[topic], missing)
    assert not [t for t in after if t.startswith(("invalid/", "rejected/"))]

    assert set(poses_after) == set(poses_before) and len(poses_before) == 2 * 200
    worst = defaultdict(float)
    for key, (x, y, _) in poses_before.items():
        ax, ay, _ = poses_after[key]
        worst[key[1]] = max(worst[key[1]], abs(ax - x), abs(ay - y))
    assert max(worst.values()) <= 1e-3, (dict(worst), localizer)
    same = sum(poses_after[key] == pose for key, pose in poses_before.items())
    assert same == len(poses_before), (f"{same} of {len(poses_before)} poses bit for bit",
                                       localizer)


def test_replay_refuses_what_it_cannot_read(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a recording" * 20)
    for args in ([str(tmp_path / "missing.mcap")], [str(junk)], [str(junk), "--speed", "0"]):
        res = subprocess.run([sys.executable, "-m", "btrack", "replay", *args],
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 2, res.stderr
        assert "btrack replay:" in res.stderr and "Traceback" not in res.stderr


def test_a_replay_at_the_recorded_pace_keeps_the_order(pf_run, tmp_path):
    """--speed: the recorded pace, scaled; every message, in the recorder's order."""
    ns, port = unique_ns(), free_port()
    out = tmp_path / "paced"
    # (a drain of 2 s: in the original recording an agent's last state can come after
    # the final tick, and a loaded host may hold the replay's last puts back a while)
    recorder = start(["record", "--out", str(out), "--ns", ns, "--mode", "router",
                      "--listen", f"tcp/127.0.0.1:{port}", "--no-multicast", "--drain", "2"],
                     log=tmp_path / "recorder.log")
    try:
        wait_for(lambda: listening(port), 30, "the recorder's router")
        replay = subprocess.run(
            [sys.executable, "-m", "btrack", "replay", str(pf_run), "--speed", "8",
             "--topics", "world/tick", "laser/scan", "agent/*/state",
             "--wait-for", "alive/recorder", "--ns", ns, "--mode", "client", "--connect",
             f"tcp/127.0.0.1:{port}", "--no-multicast"],
            capture_output=True, text=True, timeout=120)
        assert replay.returncode == 0, replay.stderr[-3000:]
        assert recorder.wait(60) == 0, (tmp_path / "recorder.log").read_text()[-2000:]
    finally:
        end(recorder)

    def sequence(path):
        with open(path, "rb") as f:
            return [(c.topic, json.loads(m.data)["k"])
                    for _, c, m in make_reader(f).iter_messages(log_time_order=True)
                    if c.topic in ("world/tick", "laser/scan") or c.topic.endswith("/state")]

    original, again = sequence(pf_run / "run.mcap"), sequence(out / "run.mcap")
    first = next((i for i, (a, b) in enumerate(zip(again, original, strict=False))
                  if a != b), None)
    assert again == original, (len(again), len(original), first,
                               original[first - 2:first + 3] if first is not None else
                               original[len(again):len(again) + 5])
    assert len(original) == 200 + 400 + 400

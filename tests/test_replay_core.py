"""replay.core: a recorded message back to the bytes its sender put, its due time at a
speed, and the pacing of a replay as fast as its listener."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from replay.core import Item, Pacer, due_s, payload_of, replayable
from wire import DecodeError, Pose, Scan, Tick, decode, encode

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _as_recorded(msg) -> bytes:
    """The recorder's JSON of a message (recorder.writer)."""
    return json.dumps(msg.__dict__, separators=(",", ":"), allow_nan=False).encode()


@given(x=finite, y=finite, theta=finite, k=st.integers(0, 10**9))
def test_a_recorded_pose_replays_as_the_bytes_it_was(x, y, theta, k):
    pose = Pose(0.1 * k, k, 2, x, y, theta, [0.0, 1e-6, 3.0], "pf")
    payload, tick = payload_of("robot/2/pose", _as_recorded(pose))
    assert payload == encode(pose) and tick == k
    assert decode(Pose, payload) == pose


def test_scans_ticks_and_unknown_maps_replay_field_for_field():
    scan = Scan(1.5, 15, [0.1 * i for i in range(361)], 3.0, -2.0, 1.5707963267948966)
    assert payload_of("laser/scan", _as_recorded(scan)) == (encode(scan), 15)
    tick = Tick(0.0, 0, [0, 1], done=True, wall_ns=123)
    assert payload_of("world/tick", _as_recorded(tick)) == (encode(tick), 0)
    payload, k = payload_of("something/else", b'{"a":1,"k":true}')
    assert k is None and payload == b"\x82\xa1a\x01\xa1k\xc3"
    with pytest.raises(DecodeError):  # a field the type does not have
        payload_of("world/tick", b'{"t":0.0,"k":0,"live":[],"extra":1}')


def test_what_is_replayed():
    assert replayable("robot/0/sense") and replayable("fault") and replayable("world/tick")
    for topic in ("/scan/0", "/scene/map", "invalid/robot/0/cmd", "rejected/agent/1/state",
                  "alive/agent/0"):
        assert not replayable(topic)


def test_due_times_follow_the_recorded_pace_at_a_speed():
    items = [Item("a", ns, None, b"") for ns in (5_000_000_000, 5_500_000_000, 7_000_000_000)]
    assert due_s(items, 1.0) == [0.0, 0.5, 2.0]
    assert due_s(items, 4.0) == [0.0, 0.125, 0.5]
    assert due_s([], 2.0) == []


def test_the_pacer_keeps_the_replay_ahead_of_its_listener_by_at_most_ahead_ticks():
    pacer = Pacer(1)
    assert pacer.may_send(None)  # untimed messages (WorldInfo) always go
    assert pacer.may_send(7)  # the first tick goes before any answer
    assert not pacer.may_send(8)
    pacer.heard(7)
    assert pacer.may_send(8) and not pacer.may_send(9)
    pacer.heard(5)  # an old answer takes nothing back
    assert pacer.may_send(8) and not pacer.may_send(9)
    three = Pacer(3)
    assert [three.may_send(k) for k in range(5)] == [True, True, True, False, False]
    three.heard(1)
    assert three.may_send(4) and not three.may_send(5)
    with pytest.raises(ValueError):
        Pacer(0)

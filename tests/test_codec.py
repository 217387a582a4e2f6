"""Wire codec: round trips, and every kind of bad payload refused with a reason."""

import math

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wire import AgentState, Cmd, DecodeError, Keys, Sense, Truth, WorldInfo, decode, encode
from wire.codec import from_record
from wire.keys import TOPICS

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)


def state(**kw):
    base = dict(t=1.0, k=10, robot=1, lo=2.0, hi=4.0, phase=1.0, phase_des=1.1, workload=0.6,
                depth_avg=0.3, direction=1, lower=0, upper=2, edge_lo=0.0, edge_hi=6.0)
    base.update(kw)
    return AgentState(**base)


@given(finite, st.integers(0, 10**9), st.integers(0, 1000), st.floats(-10, 10),
       st.floats(-100, 100))
def test_cmd_round_trip(t, k, robot, v, omega):
    msg = Cmd(abs(t), k, robot, v, omega)
    assert decode(Cmd, encode(msg)) == msg


def test_state_round_trip():
    assert decode(AgentState, encode(state())) == state()
    shared = state(turns=31.4, end_bins=[19, 20, 21], end_depths=[1.5, 1.5, 0.3])
    assert decode(AgentState, encode(shared)) == shared


def test_state_without_sweep_count_or_end_depths_still_decodes():
    old = {k: v for k, v in state().__dict__.items()
           if k not in ("turns", "end_bins", "end_depths")}
    msg = decode(AgentState, msgpack.packb(old))
    assert msg.turns == 0.0 and msg.end_bins == [] and msg.end_depths == []


def test_ints_accepted_for_floats():
    raw = msgpack.packb({**state().__dict__, "lo": 2})
    assert decode(AgentState, raw).lo == 2.0


@pytest.mark.parametrize(
    "payload, reason",
    [
        (b"\xc1garbage", "not msgpack"),
        (msgpack.packb([1, 2, 3]), "expected a map"),
        (msgpack.packb({**state().__dict__, "phase": float("nan")}), "not finite"),
        (msgpack.packb({**state().__dict__, "workload": math.inf}), "not finite"),
        (msgpack.packb({**state().__dict__, "phase": 7.0}), "phase outside"),
        (msgpack.packb({**state().__dict__, "hi": 9.0}), "boundaries outside"),
        (msgpack.packb({**state().__dict__, "lo": "x"}), "expected a number"),
        (msgpack.packb({**state().__dict__, "direction": 0}), "direction"),
        (msgpack.packb({k: v for k, v in state().__dict__.items() if k != "phase"}), "missing"),
        (msgpack.packb({**state().__dict__, "evil": 1}), "unknown field"),
        (msgpack.packb({**state().__dict__, "k": True}), "expected an integer"),
        (msgpack.packb({**state().__dict__, "end_bins": [1, 2], "end_depths": [0.3]}),
         "as long as"),
        (msgpack.packb({**state().__dict__, "end_bins": [1], "end_depths": [-0.3]}),
         "negative depth"),
        (msgpack.packb({**state().__dict__, "end_bins": [1.5], "end_depths": [0.3]}),
         "expected an integer"),
    ],
)
def test_bad_payloads_refused_with_reason(payload, reason):
    with pytest.raises(DecodeError, match=reason):
        decode(AgentState, payload)


def test_team_truth_round_trip_and_shape_checked():
    msg = Truth(0.5, 5, [0, 1, 2], [0.5, 2.5, 4.5], [-1.0, -1.0, 0.2], [0.0, 1.5, -3.0])
    assert decode(Truth, encode(msg)) == msg
    poses = [(0.5, -1.0, 0.0), (2.5, -1.0, 1.5), (4.5, 0.2, -3.0)]
    assert Truth.of_team(0.5, 5, poses) == msg
    short = msgpack.packb({**msg.__dict__, "y": [-1.0, -1.0]})
    with pytest.raises(DecodeError, match="one entry per robot"):
        decode(Truth, short)
    twice = msgpack.packb({**msg.__dict__, "robots": [0, 1, 1]})
    with pytest.raises(DecodeError, match="distinct"):
        decode(Truth, twice)
    with pytest.raises(DecodeError, match="not finite"):
        decode(Truth, msgpack.packb({**msg.__dict__, "x": [0.5, math.nan, 4.5]}))


def test_sense_carries_a_pose_or_none_and_a_bad_one_is_refused():
    bare = Sense(0.5, 5, 1, True, False, 0.02, 0.001, 0.0, 6.0, 0.1)
    assert decode(Sense, encode(bare)) == bare and bare.pose == []
    # an older Sense without the fields at all still decodes, with no pose
    old = {k: v for k, v in bare.__dict__.items() if k not in ("pose", "pose_source")}
    assert decode(Sense, msgpack.packb(old)) == bare
    posed = Sense(0.5, 5, 1, True, False, 0.02, 0.001, 0.0, 6.0, 0.1,
                  [2.5, -1.0, 1.57], "odometry")
    assert decode(Sense, encode(posed)) == posed
    for change, reason in (({"pose": [2.5, -1.0]}, "x, y and theta"),
                           ({"pose_source": "pf"}, "truth or odometry"),
                           ({"pose": []}, "x, y and theta"),
                           ({"pose": [2.5, math.inf, 0.0]}, "not finite")):
        with pytest.raises(DecodeError, match=reason):
            decode(Sense, msgpack.packb({**posed.__dict__, **change}))


def world_info(**kw):
    base = dict(map="m", start="in-phase", robots=3, localization="truth", seed=1,
                duration_s=60.0, dt=0.1, edge_lo=0.0, edge_hi=0.3, bin_m=0.1,
                patrol_depth=[0.3, 1.5, 0.3], robot_radius=0.17, min_depth=0.3,
                margin_out=0.3)
    base.update(kw)
    return WorldInfo(**base)


def test_world_info_round_trip_with_and_without_the_edge_shape():
    straight = world_info()
    assert decode(WorldInfo, encode(straight)) == straight and straight.edge_y == []
    # a recording made before edge_y existed: no field at all, a straight edge
    old = {k: v for k, v in straight.__dict__.items() if k != "edge_y"}
    assert decode(WorldInfo, msgpack.packb(old)) == straight
    curved = world_info(edge_y=[0.0, 0.25, -0.1])
    assert decode(WorldInfo, encode(curved)) == curved


@pytest.mark.parametrize(
    "edge_y, reason",
    [([0.0, math.nan, 0.0], "not finite"),
     ([0.0, math.inf, 0.0], "not finite"),
     ([0.0, 0.1], "one entry per patrol_depth bin"),
     ([0.0, 0.1, 0.2, 0.3], "one entry per patrol_depth bin"),
     ([0.0, "x", 0.0], "expected a number")],
)
def test_world_info_with_a_bad_edge_shape_is_refused(edge_y, reason):
    payload = msgpack.packb({**world_info().__dict__, "edge_y": edge_y})
    with pytest.raises(DecodeError, match=reason):
        decode(WorldInfo, payload)


def test_world_info_check_refuses_a_non_finite_edge_built_in_process():
    from wire.messages import InvalidMessage

    with pytest.raises(InvalidMessage, match="not finite"):
        world_info(edge_y=[0.0, math.nan, 0.0]).check()


@given(st.binary(max_size=200))
def test_random_bytes_never_raise_anything_else(data):
    try:
        decode(Sense, data)
    except DecodeError:
        pass


def test_keys_namespace_and_robot_of():
    keys = Keys("btrack/run-1")
    assert keys.state(3) == "btrack/run-1/agent/3/state"
    assert Keys.robot_of(keys.cmd(12)) == 12
    assert Keys.robot_of(keys.alive(4)) == 4
    assert keys.relative(keys.sense(0)) == "robot/0/sense"
    with pytest.raises(ValueError):
        Keys("bad ns*")


@given(st.sampled_from(sorted(TOPICS)), st.integers(0, 10_000))
def test_every_key_parses_back_to_its_topic_and_robot(name, robot):
    keys = Keys("btrack/run-1")
    topic = TOPICS[name]
    key = keys.key(name, robot if topic.per_robot else None)
    assert keys.parse(key) == (topic, robot if topic.per_robot else None)
    assert Keys("other").parse(key) is None
    if topic.per_robot:  # the pattern of every robot's key, for access control
        diff = [(a, b) for a, b in zip(key.split("/"), keys.pattern(name).split("/"),
                                       strict=True) if a != b]
        assert diff == [(str(robot), "*")]
        with pytest.raises(ValueError, match="needs a robot"):
            keys.key(name)
    else:
        assert keys.pattern(name) == key


def test_the_recorders_table_is_the_contracts():
    from recorder.topics import message_type

    for topic in TOPICS.values():
        path = topic.at(7) if topic.per_robot else topic.at()
        assert message_type(path) is topic.message
    assert message_type("robot/7/truth") is None and message_type("robot/x/sense") is None


def test_a_record_builds_its_message_and_one_of_another_contract_is_refused():
    msg = state()
    raw = {n: getattr(msg, n) for n in msg.__dataclass_fields__}
    assert from_record(AgentState, raw) == msg
    renamed = {("lo_m" if n == "lo" else n): v for n, v in raw.items()}
    with pytest.raises(DecodeError, match="missing \\['lo'\\], unknown \\['lo_m'\\]"):
        from_record(AgentState, renamed)


@given(st.floats(allow_nan=False, allow_infinity=False), st.integers(0, 10**6),
       st.integers(0, 300), st.floats(-10, 10), st.floats(-10, 10))
def test_encode_writes_what_msgpack_writes_of_the_fields(t, k, robot, v, omega):
    """The wire's bytes are msgpack's map of the fields in order (any msgpack peer reads
    them), and a numpy scalar where a float goes is written as the float it holds."""
    cmd = Cmd(t, k, robot, v, omega)
    fields = {"t": t, "k": k, "robot": robot, "v": v, "omega": omega}
    assert encode(cmd) == msgpack.packb(fields, use_bin_type=True)
    assert encode(Cmd(np.float64(t), k, robot, np.float64(v), omega)) == encode(cmd)
    with pytest.raises(TypeError):
        encode(Cmd(t, k, robot, object(), omega))  # type: ignore[arg-type]

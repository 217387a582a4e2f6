"""The world's ticks in order (wire.tickorder): lost ticks are gone past, forged ones
refused, and no tick, however forged, stops the real ones from being taken for long."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wire.tickorder import TickOrder


def offer_all(order: TickOrder[int], ks: list[int]) -> tuple[list[int], list[int]]:
    taken: list[int] = []
    refused: list[int] = []
    for k in ks:
        out = order.offer(k, k)
        taken += out.taken
        refused += [item for item, _ in out.refused]
    refused += [item for item, _ in order.finish()]
    return taken, refused


def test_ticks_in_order_are_all_taken() -> None:
    order: TickOrder[int] = TickOrder()
    assert order.offer(5, 5).taken == []  # the first heard waits for its next
    assert order.offer(6, 6).taken == [5, 6]
    assert offer_all(order, list(range(7, 100))) == (list(range(7, 100)), [])
    assert order.lost == 0


def test_a_forged_first_tick_cannot_set_the_clock() -> None:
    order: TickOrder[int] = TickOrder()
    taken, refused = offer_all(order, [10**6, 0, 1, 2])
    assert (taken, refused) == ([0, 1, 2], [10**6])


def test_a_lost_tick_is_gone_past_when_the_next_confirms_the_skip() -> None:
    order: TickOrder[int] = TickOrder()
    taken, refused = offer_all(order, [0, 1, 2, 5, 6, 7])
    assert (taken, refused, order.lost) == ([0, 1, 2, 5, 6, 7], [], 2)
    assert order.last == 7


def test_a_forged_skip_is_refused_when_the_skipped_tick_comes() -> None:
    order: TickOrder[int] = TickOrder()
    out = [order.offer(k, k) for k in (0, 1, 30)]
    assert out[2].taken == [] and out[2].refused == []  # held, not yet judged
    out3 = order.offer(2, 2)
    assert out3.taken == [2]
    assert out3.refused == [(30, "tick 30 after tick 1, and its next never came")]
    assert order.lost == 0


def test_far_ahead_and_old_ticks_are_refused_at_once() -> None:
    order: TickOrder[int] = TickOrder(max_gap=10)
    order.offer(0, 0)
    order.offer(1, 1)
    assert order.offer(12, 12).refused == [(12, "tick 12 after tick 1: more than 10 ahead")]
    assert order.offer(1, 1).refused == [(1, "tick 1 after tick 1: not a later one")]
    assert order.offer(2, 2).taken == [2]


def test_the_final_tick_is_taken_though_it_skips() -> None:
    order: TickOrder[int] = TickOrder()
    order.offer(0, 0)
    order.offer(1, 1)
    assert order.offer(4, 4, final=True).taken == [4]
    assert order.lost == 2


def test_a_tick_still_held_at_the_end_is_refused() -> None:
    order: TickOrder[int] = TickOrder()
    taken, refused = offer_all(order, [0, 1, 4])
    assert (taken, refused) == ([0, 1], [4])
    assert order.finish() == []


def test_a_gap_must_be_positive() -> None:
    with pytest.raises(ValueError, match="max_gap"):
        TickOrder(max_gap=0)


@settings(max_examples=300, deadline=None)
@given(
    st.integers(min_value=2, max_value=400),  # the run's length in ticks
    st.sets(st.integers(min_value=1, max_value=399), max_size=30),  # ticks lost
    st.lists(st.tuples(st.integers(min_value=0, max_value=399),  # where a forgery goes in
                       st.integers(min_value=-5, max_value=10**6)), max_size=5),
)
def test_real_ticks_are_taken_in_order_whatever_is_lost_or_forged(n, lost, forged) -> None:
    """Whatever single ticks a forger slips in and whatever is lost (but the last tick):
    what is taken rises strictly, and of the real ticks after the last forgery that was
    taken all are taken but for at most max_gap of them and one held at the end."""
    lost = {k for k in lost if k < n - 1}
    stream: list[tuple[int, bool]] = [(k, True) for k in range(n) if k not in lost]
    for at, k in sorted(forged, reverse=True):
        stream.insert(min(at, len(stream)), (k, False))
    order: TickOrder[tuple[int, bool]] = TickOrder(max_gap=50)
    taken: list[tuple[int, bool]] = []
    for k, real in stream:
        taken += order.offer(k, (k, real)).taken
    ks = [k for k, _ in taken]
    assert ks == sorted(set(ks))
    real_taken = {k for k, real in taken if real}
    real_sent = [k for k, real in stream if real]
    forged_taken = [i for i, (k, real) in enumerate(stream) if not real and (k, real) in taken]
    after = real_sent if not forged_taken else [
        k for k, real in stream[forged_taken[-1]:] if real]
    missed = [k for k in after if k not in real_taken]
    # single forgeries never come in pairs: at most one hole of max_gap, and the last
    # real tick is held only if a loss comes just before it
    assert len(missed) <= 50 + 1, (missed, stream)

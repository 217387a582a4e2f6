"""The world's ticks in order, as heard on an untrusted bus. Pure: no I/O, no clock.

A listener that follows the world's clock (the recorder, the launcher's fault clock) must
neither take a forged tick from the far future for the time, nor stop at a tick that was
lost on the way: a rule of "only the next tick" refuses every tick after a lost one, for
the rest of the run. ``TickOrder`` takes the next tick at once; a tick that skips ahead
(up to ``max_gap`` ticks) is held until its own next tick confirms it, and is refused if
the skipped next one comes instead. The first tick heard is held so too (a forged first
tick from the far future would otherwise set the clock). A forger must then send two
consecutive ticks, and gains at most ``max_gap`` ticks' hole in what follows, or, before
the first real tick, a clock the real ticks never reach: a listener that knows the run's
length refuses ticks beyond it first (the recorder does). The ticks skipped are counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T")

MAX_TICK_GAP = 50  # ticks a tick may skip ahead of the last one taken


@dataclass
class Outcome(Generic[T]):
    """What one offer decided: the items taken, in tick order, and those refused."""

    taken: list[T] = field(default_factory=list)
    refused: list[tuple[T, str]] = field(default_factory=list)


class TickOrder(Generic[T]):
    """Ticks offered with an item each (a message, a payload); see the module's rule."""

    def __init__(self, max_gap: int = MAX_TICK_GAP) -> None:
        if max_gap < 1:
            raise ValueError(f"max_gap must be 1 or more, not {max_gap}")
        self.max_gap = max_gap
        self.last: int | None = None  # the latest tick taken
        self.lost = 0  # ticks skipped between two taken ones
        self._held: tuple[int, T] | None = None

    def offer(self, k: int, item: T, final: bool = False) -> Outcome[T]:
        """Offer tick ``k``. ``final``: the run's own last tick (already judged so by
        the caller), taken at once even if it skips ahead: nothing comes after it."""
        out: Outcome[T] = Outcome()
        last = self.last
        if last is not None and k <= last:
            out.refused.append((item, f"tick {k} after tick {last}: not a later one"))
            return out
        if last is not None and k > last + self.max_gap:
            out.refused.append((item, f"tick {k} after tick {last}: more than "
                                      f"{self.max_gap} ahead"))
            return out
        held, self._held = self._held, None
        if held is not None:
            if k == held[0] + 1:  # the skip was real: ticks were lost on the way
                self._take(held[0], held[1], out)
                self._take(k, item, out)
                return out
            out.refused.append((held[1], self._unconfirmed(held[0])))
        if (last is not None and k == last + 1) or final:
            self._take(k, item, out)
        else:
            self._held = (k, item)
        return out

    def finish(self) -> list[tuple[T, str]]:
        """The run is over: a tick still waiting for its next is refused."""
        held, self._held = self._held, None
        if held is None:
            return []
        return [(held[1], self._unconfirmed(held[0]))]

    def _unconfirmed(self, k: int) -> str:
        after = "the first heard" if self.last is None else f"after tick {self.last}"
        return f"tick {k} {after}, and its next never came"

    def _take(self, k: int, item: T, out: Outcome[T]) -> None:
        if self.last is not None:
            self.lost += k - self.last - 1
        self.last = k
        out.taken.append(item)

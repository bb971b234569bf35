"""Counters keyed by something the input chooses, kept to a bounded size: top N plus "other".

A table keyed by a sentence address, a message id or a peer grows with whatever arrives: a
receiver (or line noise) that sends 200 000 distinct proprietary addresses would add one key
each. :class:`TopCounter` is a :class:`collections.Counter` that holds at most ``2 * n`` keys:
when a new key would exceed that, the ``n`` largest counts are kept and every smaller one is
folded into the key ``other``. The total (``sum(values())``) is always exact; a kept key's count
is exact since it was last admitted; ``other`` holds the rest. Memory is O(n) whatever comes in.
"""

from __future__ import annotations

from collections import Counter

OTHER = "other"


class TopCounter(Counter[str]):
    """See the module docstring. ``n`` (>= 1) keys are kept at each compaction, plus ``other``."""

    def __init__(self, n: int = 64) -> None:
        if n < 1:
            raise ValueError("n must be >= 1")
        super().__init__()
        self.n = n
        self.folded_keys = 0  # how many distinct keys were folded into "other" so far

    def __setitem__(self, key: str, value: int) -> None:
        if key not in self and len(self) >= 2 * self.n:
            self._compact()
        super().__setitem__(key, value)

    def _compact(self) -> None:
        other = super().pop(OTHER, 0)
        ranked = sorted(self.items(), key=lambda kv: (-kv[1], kv[0]))
        for k, v in ranked[self.n :]:
            other += v
            self.folded_keys += 1
            super().__delitem__(k)
        super().__setitem__(OTHER, other)

    def copy(self) -> TopCounter:
        new = TopCounter(self.n)
        dict.update(new, self)
        new.folded_keys = self.folded_keys
        return new

"""Messages lost in transport, counted from the gaps in a stream's stamps.

Sensor streams travel best effort: a message lost on the way leaves no trace but a gap in
the header stamps. :class:`GapCounter` learns a stream's period (the median of its last
stamp differences) and counts, for each difference longer than ``factor`` periods, the
messages missing in it (``round(difference / period) - 1``). Beam dropouts of a tracker
count as gaps too: the counts say how much input did not arrive, not why.
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["GapCounter"]


class GapCounter:
    """Gaps and missing messages of one stream (stamps in ns, message time).

    Parameters
    ----------
    history : int
        Stamp differences the period is the median of.
    factor : float
        A difference longer than `factor` periods is a gap.
    warmup : int
        Differences seen before gaps are counted (the period must be known).
    """

    def __init__(self, *, history: int = 64, factor: float = 1.5, warmup: int = 8) -> None:
        self._diffs: deque[int] = deque(maxlen=int(history))
        self.factor = float(factor)
        self.warmup = int(warmup)
        self._last: int | None = None
        self.gaps = 0
        """Differences longer than `factor` periods."""
        self.missing = 0
        """Messages estimated missing in those gaps."""
        self.longest_gap_s = 0.0
        """Longest gap counted [s]."""

    @property
    def period_s(self) -> float | None:
        """The stream's period [s] (median stamp difference), None until known."""
        if len(self._diffs) < self.warmup:
            return None
        return float(np.median(np.fromiter(self._diffs, dtype=np.int64))) / 1e9

    def add(self, stamp_ns: int) -> int:
        """Take the next stamp; the messages missing before it (0 when none or out of order)."""
        stamp = int(stamp_ns)
        last, self._last = self._last, stamp if self._last is None else max(self._last, stamp)
        if last is None or stamp <= last:
            return 0
        diff = stamp - last
        lost = 0
        period = self.period_s
        if period is not None and period > 0 and diff > self.factor * period * 1e9:
            lost = max(round(diff / (period * 1e9)) - 1, 1)
            self.gaps += 1
            self.missing += lost
            self.longest_gap_s = max(self.longest_gap_s, diff / 1e9)
        else:
            self._diffs.append(diff)  # gaps do not stretch the period
        return lost

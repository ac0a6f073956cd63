"""Merge the joint-state and tracker-point streams back into publication order.

The static-pose collector's result depends on how the two streams interleave (which data
a window holds when it is checked). A recorded bag fixes that order (log time), and the
replay feeds messages in it; live, DDS gives no order across two topics, and an executor
with both subscriptions ready takes them in its own order. So the collector node does not
feed messages as the executor hands them over: it queues each stream (first in, first
out) and releases them merged by their *publication* time (the DDS source timestamp where
rclpy reports it, Jazzy and later; else the local arrival time, i.e. arrival order).

Release rule: with both queues non-empty, the head with the earlier key goes first (a
stream's messages arrive in the order they were published, so nothing earlier of the
other stream can still be in transit). A head waits while the other queue is empty until
it has been held `hold_s` of wall time, the allowance for the other stream's transport
latency, or until :meth:`drain`. With one publisher per topic this reproduces the order in
which the messages were published exactly; ``hold_s = 0`` feeds arrival order.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from robocal_uncertainty.errors import ConfigError

__all__ = ["StreamMerger"]


class StreamMerger:
    """Two FIFO queues released in merged key order (see the module docstring).

    Parameters
    ----------
    sink : callable
        ``sink(stream, item)`` receives each item when released (stream 0 or 1).
    hold_ns : int
        Longest wall time [ns] a message waits for the other stream.
    """

    def __init__(self, sink: Callable[[int, Any], None], *, hold_ns: int) -> None:
        if hold_ns < 0:
            msg = f"hold_ns must be >= 0, got {hold_ns}"
            raise ConfigError(msg)
        self._sink = sink
        self.hold_ns = int(hold_ns)
        self._queues: tuple[deque[tuple[int, int, int, Any]], ...] = (deque(), deque())
        self._seq = 0

    def __len__(self) -> int:
        return len(self._queues[0]) + len(self._queues[1])

    def push(self, stream: int, key_ns: int, arrival_ns: int, item: Any) -> None:
        """Queue `item` of `stream` with its publication key and arrival time [ns]; release
        what can go."""
        self._queues[stream].append((int(key_ns), self._seq, int(arrival_ns), item))
        self._seq += 1
        self.release(arrival_ns)

    def release(self, now_ns: int) -> None:
        """Release every message that can go at wall time `now_ns`."""
        self._release(now_ns)

    def drain(self) -> None:
        """Release everything queued, in merged order."""
        self._release(None)

    def _release(self, now_ns: int | None) -> None:
        """Release in merged order; a lone head waits out `hold_ns` unless `now_ns` is None."""
        a, b = self._queues
        while a or b:
            if a and b:
                stream = 0 if (a[0][0], a[0][1]) <= (b[0][0], b[0][1]) else 1
            else:
                stream = 0 if a else 1
                if now_ns is not None and now_ns - self._queues[stream][0][2] < self.hold_ns:
                    return
            self._sink(stream, self._queues[stream].popleft()[3])

    def clear(self) -> None:
        """Forget everything queued."""
        for queue in self._queues:
            queue.clear()

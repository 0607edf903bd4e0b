"""The threaded-source base (edge/sources/threaded.py) with real threads: an error in a producer
reaches the consumer after what came before it, a full queue blocks the producer and drops
nothing, and iteration ends when every producer is done. Waits are on events and joins, never on
a sleep."""

from __future__ import annotations

import threading

import pytest

from edge.sources import threaded
from edge.sources.threaded import ThreadedSource

WAIT_S = 10.0


class Counting(ThreadedSource):
    """Producers that each put `count` numbers tagged with their name, then maybe raise."""

    def __init__(self, names: list[str], count: int, stop: threading.Event, queue_size: int = 1000,
                 fail: Exception | None = None):
        super().__init__(stop, queue_size)
        self.put_count = 0
        self._lock = threading.Lock()
        for name in names:
            self.start(self._produce_numbers, name, count, fail, name=name)

    def _produce_numbers(self, name: str, count: int, fail: Exception | None) -> None:
        for i in range(count):
            self.put((name, i))
            with self._lock:
                self.put_count += 1
        if fail is not None:
            raise fail


def test_done_ends_the_iteration_after_every_producer():
    source = Counting(["a", "b", "c"], 50, threading.Event())
    items = list(source)
    assert sorted(items) == sorted((name, i) for name in "abc" for i in range(50))
    for name in "abc":  # each producer's items in its own order
        assert [i for n, i in items if n == name] == list(range(50))
    assert source.join(WAIT_S) and source.dropped_at_shutdown == 0


def test_an_exception_in_the_thread_reaches_the_consumer_after_its_data():
    source = Counting(["a"], 5, threading.Event(), fail=RuntimeError("port on fire"))
    received = []
    with pytest.raises(RuntimeError, match="port on fire"):
        for item in source:
            received.append(item)
    assert received == [("a", i) for i in range(5)]
    assert source.join(WAIT_S)


def test_a_full_queue_blocks_the_producer_and_nothing_is_dropped():
    capacity, count = 2, 300
    source = Counting(["a"], count, threading.Event(), queue_size=capacity)
    received = []
    for item in source:
        received.append(item)
        # the producer never runs further ahead than the queue holds: its put blocked
        assert source.put_count <= len(received) + capacity
    assert received == [("a", i) for i in range(count)]
    assert source.dropped_at_shutdown == 0 and source.join(WAIT_S)


def test_a_producer_blocked_on_a_full_queue_ends_when_the_consumer_leaves():
    source = Counting(["a"], 100, threading.Event(), queue_size=1)
    first = next(iter(source))
    source.leave()
    assert source.join(WAIT_S)
    assert first == ("a", 0) and source.dropped_at_shutdown > 0  # counted, not silently lost


def test_after_stop_a_queue_nobody_drains_is_given_up_on(monkeypatch):
    monkeypatch.setattr(threaded, "SHUTDOWN_GRACE_S", 0.2)
    stop = threading.Event()
    stop.set()
    source = Counting(["a"], 10, stop, queue_size=1)
    assert source.join(WAIT_S)  # the producer ended although nobody took its items
    assert source.dropped_at_shutdown == 10  # 9 numbers and its end marker: counted
    assert list(source) == [("a", 0)]  # what was queued is still there; the iteration ends

"""The one way a device source hands its work to the edge: threads -> a bounded queue -> the consumer's loop.

    class Readers(ThreadedSource):
        def __init__(self, stop):
            super().__init__(stop)
            self.start(self._read, "port A")       # any number of producer threads
        def _read(self, port):
            while not self.stop.is_set():
                self.put(read_one(port))           # blocks while the queue is full
    for item in Readers(stop):                     # until every producer has returned
        ...

`put` blocks while the queue is full: a consumer that falls behind slows the device's reader
(back-pressure), nothing is dropped. A producer's exception is put after what it produced and
raised in the consumer; iteration ends once every producer has returned. A producer gives up a
put only when nobody will take it: the consumer has said it is leaving (`leave()`), or `stop` is
set and the queue has not moved for SHUTDOWN_GRACE_S (counted in `dropped_at_shutdown`), so
that its thread can end and be joined.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from typing import Any, Callable

POLL_S = 0.05  # how often a blocked producer or the consumer looks at `stop` and at the threads
SHUTDOWN_GRACE_S = 2.0  # after stop, a full queue nobody drains for this long is given up on
QUEUE_SIZE = 1000


class ThreadedSource:
    """Base of the serial, BLE and phone sources; see the module docstring."""

    _DONE = object()  # a producer's last item

    def __init__(self, stop: threading.Event, queue_size: int = QUEUE_SIZE):
        self.stop = stop
        self.queue: queue.Queue[Any] = queue.Queue(maxsize=queue_size)
        self.dropped_at_shutdown = 0
        self._threads: list[threading.Thread] = []
        self._left = threading.Event()

    def start(self, work: Callable[..., None], *args: Any, name: str | None = None) -> threading.Thread:
        """Run `work(*args)` on a daemon thread of its own as one producer."""
        thread = threading.Thread(target=self._produce, args=(work, args), name=name, daemon=True)
        self._threads.append(thread)
        thread.start()
        return thread

    def _produce(self, work: Callable[..., None], args: tuple[Any, ...]) -> None:
        try:
            work(*args)
        except BaseException as error:  # handed to the consumer, raised there
            self.put(error)
        finally:
            self.put(self._DONE)

    def put(self, item: Any) -> None:
        """Queue `item`, waiting while the queue is full (see the module docstring for when it gives up)."""
        waited = 0.0
        while not self._left.is_set():
            try:
                self.queue.put(item, timeout=POLL_S)
                return
            except queue.Full:
                waited = waited + POLL_S if self.stop.is_set() else 0.0
                if waited >= SHUTDOWN_GRACE_S:
                    break
        self.dropped_at_shutdown += 1

    def __iter__(self) -> Iterator[Any]:
        running = len(self._threads)
        while running:
            try:
                item = self.queue.get(timeout=POLL_S)
            except queue.Empty:
                if not any(thread.is_alive() for thread in self._threads) and self.queue.empty():
                    return  # a producer's last items were given up on at shutdown
                continue
            if item is self._DONE:
                running -= 1
            elif isinstance(item, BaseException):
                raise item
            else:
                yield item

    def leave(self) -> None:
        """The consumer takes nothing more: producers' puts return at once (counted as dropped)."""
        self._left.set()

    def join(self, timeout: float | None = None) -> bool:
        """Wait for every producer to end (after `stop`); True if they have."""
        for thread in self._threads:
            thread.join(timeout)
        return not any(thread.is_alive() for thread in self._threads)

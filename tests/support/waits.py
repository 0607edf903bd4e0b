"""Waiting on a condition without sleeping a guessed time."""

from __future__ import annotations

import time
from collections.abc import Callable

POLL_S = 0.005  # how often the predicate is checked; a passing wait ends within one poll


def wait_until(predicate: Callable[[], object], timeout_s: float, what: str) -> None:
    """Return as soon as `predicate()` is true; fail naming `what` after `timeout_s`.

    For state that gives no signal to wait on (a reader thread's counters, a file appearing).
    Where there is a signal (an event, a queue, a liveliness token, a first sample), wait on it.
    """
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout_s:g} s for {what}")
        time.sleep(POLL_S)

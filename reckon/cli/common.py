"""What several commands share: progress lines, `--set key=value` pairs, stopping on a signal."""

from __future__ import annotations

import argparse
import sys
import time

from protocol.errors import ReckonError


class Progress:
    """Progress lines on stderr, at most one per `every_s` unless forced."""

    def __init__(self, enabled: bool, every_s: float = 1.0):
        self.enabled, self.every_s, self.last = enabled, every_s, 0.0
        self.start = time.monotonic()

    def __call__(self, text: str) -> None:
        now = time.monotonic()
        if self.enabled and now - self.last >= self.every_s:
            self.last = now
            print(f"[{now - self.start:6.1f} s] {text}", file=sys.stderr, flush=True)


def overrides(pairs: list[str]) -> dict[str, str]:
    """`--set` pairs -> {key: value}; ReckonError naming a pair without `=`."""
    result = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ReckonError(f"--set {pair!r}: expected key=value")
        result[key.strip()] = value.strip()
    return result


def key_value(text: str) -> str:
    """An argparse type: KEY=VALUE, kept as the text."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY=VALUE")
    return text


def stop_on_signals():
    """An Event set by Ctrl-C or SIGTERM, so a recorder can finish its file."""
    import signal
    import threading

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop

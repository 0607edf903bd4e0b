"""Whether anyone subscribes to a key expression, followed as subscribers come and go.

A publisher declared on the key expression (wildcards allowed) only for its matching status; it
sends nothing. Zenoh calls the listener back on each change (on its own thread), so a caller reads
a flag instead of asking Zenoh's routing tables, under their lock, for every message. Used where a
stream is worth making only for someone: an edge's raw IMU (reckon/processes/raw_feed.py), the
hub's pose tracks (reckon/processes/hub.py).
"""

from __future__ import annotations

import zenoh

from reckon.transport.session import BusError, BusSession


class Listened:
    """`matching`: a subscriber somewhere matches `key_expr` now (as far as Zenoh's routing knows)."""

    def __init__(self, session: BusSession, key_expr: str):
        self.key_expr = key_expr
        try:
            self._publisher = session.declare_publisher(key_expr)
            self._listener = self._publisher.declare_matching_listener(self._changed)
        except zenoh.ZError as error:
            raise BusError(f"cannot follow the subscribers of {key_expr!r}: {error}") from None
        # After the listener: a change between the two is then either seen by it or in this answer.
        self.matching: bool = self._publisher.matching_status.matching

    def _changed(self, status: zenoh.MatchingStatus) -> None:
        self.matching = status.matching

    def close(self) -> None:
        self._listener.undeclare()
        self._publisher.undeclare()

    def __enter__(self) -> "Listened":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

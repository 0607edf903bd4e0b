"""Queries: a key that answers at once with a fixed reply, and asking one.

A reply travels on the same link as the samples before it, behind them: an answer is therefore
also a barrier (`reckon.transport.liveliness.flush` builds on that).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import zenoh

from reckon.transport.session import BusError, BusSession
from reckon.transport.subscriptions import Received, received_from


class Answer:
    """A queryable on `key` that replies to every query with `payload` (and `encoding`, when given).

    Replying from the callback is safe: the reply is one small message, and zenoh-python runs
    Python callbacks on their own thread, not on Zenoh's network thread. BusError naming the key
    when it cannot be declared.
    """

    def __init__(self, session: BusSession, key: str, payload: bytes = b"", encoding: str | None = None):
        self.key = key
        self._payload = payload
        self._encoding = None if encoding is None else zenoh.Encoding(encoding)
        try:
            self._queryable = session.declare_queryable(key, self._answer)
        except zenoh.ZError as error:
            raise BusError(f"cannot answer on {key!r}: {error}") from None

    def _answer(self, query: Any) -> None:
        with query:  # leaving `with` sends the final reply at once
            if self._encoding is None:
                query.reply(self.key, self._payload)
            else:
                query.reply(self.key, self._payload, encoding=self._encoding)

    def close(self) -> None:
        self._queryable.undeclare()

    def __enter__(self) -> Answer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def query(session: BusSession, selector: str, timeout_s: float) -> Iterator[Received]:
    """Ask whoever answers on `selector` (Zenoh's default target and consolidation); each good
    reply as it comes, error replies skipped. Ends when every answerer is done or after `timeout_s`;
    a caller that stops early stops waiting for the rest."""
    for reply in session.get(selector, timeout=timeout_s):
        if reply.ok is not None:
            yield received_from(reply.ok)

"""Ready signals: liveliness tokens ("this process is up"), waiting for them, and flush barriers.

Tests and start-up wait on these, never on sleep (style rule 15).
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable, Sequence

import zenoh

from protocol import bus as wire
from reckon.transport.queries import Answer
from reckon.transport.session import BusError, BusSession


class Alive:
    """This process is up: a liveliness token plus a queryable on the same key that answers at once.

    The answer is a flush barrier for whoever asks (`flush`): it comes back only after every
    sample the asker sent earlier on the same link has been handed to this process's handlers.
    """

    def __init__(self, session: BusSession, venue: str, role: wire.Role, process_id: str | None = None):
        self.key = wire.alive(venue, role, process_id or str(session.zid()))
        self._answer = Answer(session, self.key, b"")
        self._token = session.liveliness().declare_token(self.key)

    def close(self) -> None:
        self._token.undeclare()
        self._answer.close()

    def __enter__(self) -> "Alive":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TokenWatch:
    """`on_change(key, up)` for every liveliness token matching `selector`: up=True when one
    appears, False when it goes (its process stopped or lost the link). Tokens already present
    are reported first (history).

    `on_change` runs on Zenoh's callback thread: it must return at once (never block, never
    publish). BusError naming the selector when it cannot be declared.
    """

    def __init__(self, session: BusSession, selector: str, on_change: Callable[[str, bool], None]):
        self.selector = selector

        def on_sample(sample: zenoh.Sample) -> None:
            on_change(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        try:
            self._subscriber = session.liveliness().declare_subscriber(selector, on_sample, history=True)
        except zenoh.ZError as error:
            raise BusError(f"cannot watch liveliness on {selector!r}: {error}") from None

    def close(self) -> None:
        self._subscriber.undeclare()

    def __enter__(self) -> TokenWatch:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def wait_for_peers(session: BusSession, selector: str | Sequence[str], count: int,
                   timeout_s: float | None) -> list[str]:
    """Wait until `count` distinct liveliness tokens match `selector` (one or several); their keys.

    Tokens already present count (history). A token that goes away stops counting. BusError after
    `timeout_s` seconds (None: wait for ever) naming the selector and what was seen.
    """
    selectors = [selector] if isinstance(selector, str) else list(selector)
    events: queue.Queue[tuple[str, bool]] = queue.Queue()  # unbounded: a few events per process
    watches = [TokenWatch(session, s, lambda key, up: events.put((key, up))) for s in selectors]  # never blocks
    try:
        present: set[str] = set()
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while len(present) < count:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                key, up = events.get(timeout=remaining)
            except queue.Empty:
                raise BusError(f"waited {timeout_s:.1f} s for {count} live peer(s) on {', '.join(selectors)}; "
                               f"saw {len(present)}: {', '.join(sorted(present)) or 'none'}") from None
            if up:
                present.add(key)
            else:
                present.discard(key)
        return sorted(present)
    finally:
        for watch in watches:
            watch.close()


def flush(session: BusSession, selector: str, timeout_s: float) -> list[str]:
    """Ask every `Alive` process matching `selector` for a flush barrier; keys of those that answered.

    When a key is in the answer, every sample this session published before the call has reached
    that process. Call it before closing a publishing session: closing drops what is still queued.
    """
    replies = session.get(selector, target=zenoh.QueryTarget.ALL,
                          consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout_s)
    return sorted(str(reply.ok.key_expr) for reply in replies if reply.ok is not None)

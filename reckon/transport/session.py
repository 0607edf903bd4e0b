"""A Zenoh session's lifetime, and what every other part of the adapter shares: its error, sample times.

Every session is closed (`open_session` is a context manager): a subscriber left declared at
interpreter exit hangs it (field-notes.md, Zenoh section).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TypeAlias

import zenoh

from protocol.errors import ReckonError
from reckon.transport.config import BusConfig

BusSession: TypeAlias = zenoh.Session  # what the adapter's operations take; callers need not import zenoh


class BusError(ReckonError):
    """A Zenoh session cannot be opened, or a peer did not show up in time."""


@contextmanager
def open_session(config: BusConfig) -> Iterator[BusSession]:
    """Open a Zenoh session and always close it. BusError if it cannot open (e.g. port in use)."""
    try:
        session = zenoh.open(config)
    except zenoh.ZError as error:
        raise BusError(f"cannot open zenoh session (listen {config.get_json('listen/endpoints')}, "
                       f"connect {config.get_json('connect/endpoints')}): {error}") from None
    try:
        yield session
    finally:
        session.close()


def source_ns(sample: Any) -> int | None:
    """Publisher's clock at the put (ns since the Unix epoch), or None if it did not stamp.

    `sample`: a Zenoh sample (what a handler or a query reply holds)."""
    stamp = sample.timestamp
    return None if stamp is None else int(stamp.get_time_as_ntp64().as_nanos())


def zenoh_version() -> str | None:
    """The zenoh module's `__version__`, or None where the binding does not set one (1.10 does not)."""
    return zenoh.__version__ if hasattr(zenoh, "__version__") else None

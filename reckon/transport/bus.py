"""The Zenoh adapter's API: the one place the rest of reckon gets the bus from.

The wire format (payloads, encodings, control keys) is `protocol.bus`; the adapter only moves
bytes. Only the modules of `reckon/transport/` import zenoh, each with one job:

- `config`: session configs (explicit endpoints, no scouting; or a venue's JSON5 file), free ports;
- `session`: opening and always closing a session, `BusError`, a sample's publisher time;
- `publisher`: puts and deletes with congestion control BLOCK (wait, never drop);
- `subscriptions` and `polled`: samples copied out of Zenoh handlers, FIFO or ring on purpose;
- `queries`: a key that answers at once, and asking one;
- `liveliness`: ready signals (tokens, waiting for them, flush barriers).

Rules they follow (field-notes.md, Zenoh section): every session closed; measurements never
dropped (a slow consumer holds the publisher back; a dropping ring only for status views);
nothing blocks inside a Zenoh callback; tests and start-up wait on ready signals, never on sleep.
"""

from __future__ import annotations

from reckon.transport.config import (DEFAULT_ENDPOINT, MODES, BusConfig, free_endpoint, zenoh_config,
                                     zenoh_config_from_file)
from reckon.transport.liveliness import Alive, TokenWatch, flush, wait_for_peers
from reckon.transport.polled import PolledSubscription
from reckon.transport.publisher import Publisher
from reckon.transport.queries import Answer, query
from reckon.transport.session import BusError, BusSession, open_session, source_ns, zenoh_version
from reckon.transport.subscriptions import (FIFO_CAPACITY, QUEUE_CAPACITY, CallbackSubscription, DirectSubscription,
                                            Received, Subscription, SubscriptionStats)

__all__ = [
    "DEFAULT_ENDPOINT", "MODES", "BusConfig", "free_endpoint", "zenoh_config", "zenoh_config_from_file",
    "Alive", "TokenWatch", "flush", "wait_for_peers", "PolledSubscription", "Publisher", "Answer", "query",
    "BusError", "BusSession", "open_session", "source_ns", "zenoh_version",
    "FIFO_CAPACITY", "QUEUE_CAPACITY", "CallbackSubscription", "DirectSubscription", "Received", "Subscription",
    "SubscriptionStats",
]

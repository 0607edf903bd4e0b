"""Publishing protocol messages on their keys, never dropping: congestion control BLOCK.

When a link is full a put waits rather than drops, so a slow consumer slows the publisher down
(back-pressure) instead of losing data. Limit: Zenoh closes a link whose transmit queue stays
blocked for `transport.link.tx.queue.congestion_control.block.wait_before_close` (5 s by default),
so a consumer must not stall for seconds.
"""

from __future__ import annotations

from typing import Any

import zenoh

from protocol import bus as wire
from reckon.transport.session import BusError, BusSession


class Publisher:
    """Publish protocol messages on their keys with `Session.put`, congestion control BLOCK: when the
    link is full `publish` waits rather than drops.

    No Zenoh publisher or key expression is declared per key. Measured with eclipse-zenoh 1.10 on
    the bench VM (docs/benchmarks.md, Load): a process holding a declared publisher or key
    expression per key (the hub: live, refined and correction keys of 500 agents) spent about
    50 µs of its Zenoh receive thread on every sample it received, against 3 µs with plain puts;
    a put costs the publishing thread the same either way. Each key's `KeyExpr` is built (and
    checked) once and kept, as is each encoding's `Encoding`.
    """

    def __init__(self, session: BusSession):
        self._session = session
        self._keys: dict[str, zenoh.KeyExpr] = {}
        self._zenoh_encodings: dict[str, zenoh.Encoding] = {}
        self._encodings: dict[type, zenoh.Encoding] = {}  # message class -> its encoding (wire.encode's answer)
        self._block = zenoh.CongestionControl.BLOCK
        self.sent = 0

    def publish(self, key: str, message: Any) -> None:
        zenoh_encoding = self._encodings.get(type(message))
        if zenoh_encoding is None:  # once per message class: wire.encode checks it is a protocol message
            zenoh_encoding = self._encodings[type(message)] = self._encoding(wire.encode(message)[1])
        self._put(key, message.SerializeToString(), zenoh_encoding)

    def publish_bytes(self, key: str, payload: bytes, encoding: str) -> None:
        """Publish an already-encoded payload (the replayer's path: no decode and re-encode)."""
        self._put(key, payload, self._encoding(encoding))

    def _encoding(self, encoding: str) -> zenoh.Encoding:
        zenoh_encoding = self._zenoh_encodings.get(encoding)
        if zenoh_encoding is None:
            zenoh_encoding = self._zenoh_encodings[encoding] = zenoh.Encoding(encoding)
        return zenoh_encoding

    def _put(self, key: str, payload: bytes, zenoh_encoding: zenoh.Encoding) -> None:
        key_expr = self._keys.get(key)
        if key_expr is None:
            try:
                key_expr = self._keys[key] = zenoh.KeyExpr(key)
            except zenoh.ZError as error:
                raise BusError(f"cannot publish on key {key!r}: {error}") from None
        try:
            self._session.put(key_expr, payload, encoding=zenoh_encoding, congestion_control=self._block)
        except zenoh.ZError as error:
            raise BusError(f"cannot publish on key {key!r}: {error}") from None
        self.sent += 1

    def delete(self, key: str) -> None:
        """Publish a DELETE on `key` (e.g. the end-of-session marker), congestion control BLOCK as
        for puts. Not counted in `sent`, which counts messages."""
        try:
            self._session.delete(key, congestion_control=self._block)
        except zenoh.ZError as error:
            raise BusError(f"cannot delete on key {key!r}: {error}") from None

    def close(self) -> None:
        self._keys.clear()

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

"""Wire format of the Zenoh bus: payloads, their encoding, and the control keys beside the data keys.

Payload: the protobuf bytes of one `protocol.messages` message, nothing around them. The message
type travels in the Zenoh *encoding* of the sample, `application/protobuf;reckon.v1.ImuBatch`
(Zenoh's predefined `application/protobuf` plus the full protobuf name as its schema). Why the
encoding rather than an attachment: the encoding is Zenoh's own slot for "how to read these
bytes", so any Zenoh tool sees it without knowing our conventions; it costs a few bytes per
sample; it leaves the attachment free for later uses; and it names the schema exactly as the MCAP
schema record does, so a recorder maps a sample to an MCAP channel with no table.

Control keys (beside the data keys of `protocol.keys`, same `reckon/<venue>/...` root):

- `reckon/<venue>/session`: the session description (`protocol.session.to_json`) with encoding
  `application/json;reckon.session`. The source of a session (the replayer today, the hub's venue
  loader later) PUTs it once when it starts, answers queries on the same key for late joiners,
  and sends a DELETE on the key when the session is over (end of stream). Three key chunks, so it
  can never collide with an agent key (four or more chunks).
- `reckon/<venue>/alive/<role>/<id>`: "this process is up". A Zenoh liveliness token (gone when
  the process stops or loses the link), plus a queryable on the same key that answers at once: a
  query to it is a flush barrier, because the reply comes back only after every sample sent
  earlier on the same link has reached that process. Roles are the closed set `Role`.

These builders live here, beside the encodings and the flush barrier that give the control keys
their meaning; `protocol/keys.py` builds the data keys of the agents' streams. Both follow the same
style (typed builders, ids checked by `protocol.keys.check_id`).
"""

from __future__ import annotations

import enum
import json
from typing import Any

from protocol import messages
from protocol.errors import InputError
from protocol.keys import ROOT, check_id
from protocol.session import Session, session_from_dict, to_json

PROTOBUF = "application/protobuf"
SESSION_ENCODING = "application/json;reckon.session"
SESSION_CHUNK = "session"
ALIVE_CHUNK = "alive"


class Role(str, enum.Enum):
    """What kind of process holds a liveliness token."""

    EDGE = "edge"  # one per agent: reads its devices, publishes its streams
    HUB = "hub"  # subscribes to every agent, publishes poses and corrections
    RECORDER = "recorder"  # writes a venue's traffic to a session log
    REPLAY = "replay"  # publishes a session log as if it were live


# ---------------------------------------------------------------------------------------------
# Keys


def session_key(venue: str) -> str:
    """Key of the session description and its end-of-session DELETE: `reckon/<venue>/session`."""
    return f"{ROOT}/{check_id(venue, 'venue')}/{SESSION_CHUNK}"


def alive(venue: str, role: Role, process_id: str) -> str:
    """Liveliness key of one process: `reckon/<venue>/alive/<role>/<id>`; ConfigError on a bad id."""
    return f"{ROOT}/{check_id(venue, 'venue')}/{ALIVE_CHUNK}/{Role(role).value}/{check_id(process_id, 'process id')}"


def alive_selector(venue: str, role: Role | None = None) -> str:
    """Selector for the liveliness tokens of every process of one role (or of any role when None)."""
    role_chunk = "*" if role is None else Role(role).value
    return f"{ROOT}/{check_id(venue, 'venue')}/{ALIVE_CHUNK}/{role_chunk}/*"


def parse_alive(key: str) -> tuple[str, Role, str]:
    """Split a liveliness key into (venue, role, id); ValueError if it is not one."""
    parts = key.split("/")
    if len(parts) != 5 or parts[0] != ROOT or parts[2] != ALIVE_CHUNK:
        raise ValueError(f"key {key!r} is not {ROOT}/<venue>/{ALIVE_CHUNK}/<role>/<id>")
    try:
        role = Role(parts[3])
    except ValueError:
        raise ValueError(f"key {key!r}: role {parts[3]!r} is not one of "
                         f"{', '.join(r.value for r in Role)}") from None
    return parts[1], role, parts[4]


# ---------------------------------------------------------------------------------------------
# Payloads


def encoding_for(type_name: str) -> str:
    """Encoding string of a message type: `application/protobuf;reckon.v1.<type_name>`."""
    if type_name not in messages.CLASSES:
        raise ValueError(f"message type {type_name!r} is not one of {', '.join(messages.CLASSES)}")
    return f"{PROTOBUF};{messages.PACKAGE}.{type_name}"


def encode(message: Any) -> tuple[bytes, str]:
    """(payload, encoding) of one protocol message."""
    return message.SerializeToString(), encoding_for(messages.type_name(message))


def message_class(encoding: str) -> Any:
    """Protobuf class named by an encoding string; InputError naming the encoding if not ours."""
    prefix, _, schema = encoding.partition(";")
    short = schema.removeprefix(messages.PACKAGE + ".")
    if prefix != PROTOBUF or short == schema or short not in messages.CLASSES:
        raise InputError(f"encoding {encoding!r} is not {PROTOBUF};{messages.PACKAGE}.<one of "
                         f"{', '.join(messages.CLASSES)}>")
    return messages.CLASSES[short]


def decode(encoding: str, payload: bytes, where: str = "sample") -> Any:
    """The message in `payload`. InputError naming `where` for a foreign encoding or bad bytes.

    A message with a newer `schema_version` decodes (protobuf skips unknown fields); the caller
    decides whether to use it.
    """
    cls = message_class(encoding)
    try:
        return cls.FromString(payload)
    except Exception as error:  # protobuf raises DecodeError, a bare Exception subclass
        raise InputError(f"{where}: {len(payload)} bytes are not a valid {cls.DESCRIPTOR.full_name} "
                         f"({error})") from None


def encode_session(session: Session) -> bytes:
    """Payload of the session description (UTF-8 JSON, the MCAP metadata form)."""
    return to_json(session).encode("utf-8")


def decode_session(payload: bytes, where: str = "session description") -> Session:
    """Session from its payload; InputError (or ConfigError from strict loading) naming `where`."""
    try:
        data = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"{where}: not UTF-8 JSON ({error})") from None
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(data).__name__}")
    return session_from_dict(data, where=where)

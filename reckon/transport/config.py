"""Zenoh session configs: explicit endpoints, no scouting, or a venue's JSON5 file; free loopback ports.

Explicit tcp endpoints, multicast and gossip scouting off: opening takes milliseconds and works in
containers (field-notes.md, Zenoh section). Default endpoint `tcp/127.0.0.1:7447` (Zenoh's usual
port on loopback): the hub and the recorder *listen* on it, edges and the replayer *connect* to
it. A real venue passes its own, e.g. listen `tcp/0.0.0.0:7447` on the hub, connect
`tcp/<hub ip>:7447` on a Pi.
"""

from __future__ import annotations

import json
import re
import socket
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeAlias

import json5
import zenoh

from protocol.errors import ConfigError

BusConfig: TypeAlias = zenoh.Config  # what `open_session` takes; callers need not import zenoh to name it

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
MODES = ("peer", "client", "router")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|unixsock-stream|ws)/\S+$")
RETRY_INIT_MS = 250  # first reconnect after 250 ms (Zenoh's default 1 s): an edge started before
RETRY_MAX_MS = 2000  # its hub joins within 2 s of the hub coming up (Zenoh's default 4 s)


def zenoh_config(mode: str = "peer", listen: Sequence[str] = (), connect: Sequence[str] = (),
                 timestamping: bool = True) -> BusConfig:
    """A Zenoh config with explicit endpoints and no scouting.

    mode: `peer` (default; every process talks directly to the ones it connects to or accepts),
      `client` (only through a router), `router` (relays for clients).
    listen: endpoints to accept connections on, e.g. `tcp/127.0.0.1:7447` (hub, recorder).
    connect: endpoints to dial, e.g. `tcp/127.0.0.1:7447` (edges, replayer); a peer that finds
      nobody keeps retrying in the background (250 ms, doubling to 2 s).
    timestamping: stamp every sample this session publishes with its hybrid logical clock, so a
      subscriber sees when it left (`Received.source_ns`).
    ConfigError when the mode is unknown, an endpoint is malformed, or there is no endpoint at
    all (with scouting off such a session could never meet anyone).
    """
    _check_mode_and_endpoints(mode, listen, connect)
    if not listen and not connect:
        raise ConfigError("zenoh config: no listen and no connect endpoint (scouting is off, so "
                          f"give at least one, e.g. listen {DEFAULT_ENDPOINT})")
    retry = {"period_init_ms": RETRY_INIT_MS, "period_max_ms": RETRY_MAX_MS, "period_increase_factor": 2}
    document = {
        "mode": mode,
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": list(connect), "retry": retry},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "timestamping": {"enabled": bool(timestamping)},
    }
    return zenoh.Config.from_json5(json.dumps(document))


def _check_mode_and_endpoints(mode: str, listen: Sequence[str], connect: Sequence[str]) -> None:
    if mode not in MODES:
        raise ConfigError(f"zenoh mode {mode!r} is not one of {', '.join(MODES)}")
    for where, endpoints in (("listen", listen), ("connect", connect)):
        if isinstance(endpoints, str):
            raise ConfigError(f"zenoh {where}: expected a list of endpoints, got the string {endpoints!r}")
        for endpoint in endpoints:
            if not _ENDPOINT.match(endpoint):
                raise ConfigError(f"zenoh {where} endpoint {endpoint!r} is not <protocol>/<address>, "
                                  f"e.g. {DEFAULT_ENDPOINT}")


# What a config file gets from us unless it sets the key itself: the same as `zenoh_config`.
FILE_DEFAULTS = {"scouting/multicast/enabled": False, "scouting/gossip/enabled": False, "timestamping/enabled": True}
# Keys of a config file that name files Zenoh opens only when the session starts: checked at once.
FILE_PATH_KEYS = ("transport/link/tls/root_ca_certificate", "transport/link/tls/listen_private_key",
                  "transport/link/tls/listen_certificate", "transport/link/tls/connect_private_key",
                  "transport/link/tls/connect_certificate", "transport/auth/usrpwd/dictionary_file")


def zenoh_config_from_file(path: str | Path, mode: str | None = None, listen: Sequence[str] = (),
                           connect: Sequence[str] = ()) -> BusConfig:
    """A Zenoh config from a JSON5 file (a venue's router, hub or edge config, e.g. deploy/zenoh/).

    Loaded with `zenoh.Config.from_file`, so every key is Zenoh's own (schema of eclipse-zenoh 1.10).
    Where the file is silent, scouting stays off and timestamping on, as in `zenoh_config`; what
    the file sets wins. `mode`, `listen` and `connect` (from the command line) replace the file's
    values when given. ConfigError naming the file and the problem when it cannot be read, is not
    JSON5, has a key or value Zenoh refuses, names a certificate or password file that does not
    exist, or an override is malformed.
    """
    path = Path(path)
    if path.suffix not in (".json5", ".json"):
        raise ConfigError(f"zenoh config {path}: expected a .json5 or .json file")
    try:
        document = json5.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise ConfigError(f"zenoh config {path}: cannot read it ({error.strerror})") from None
    except ValueError as error:
        raise ConfigError(f"zenoh config {path}: not valid JSON5: {error}") from None
    if not isinstance(document, dict):
        raise ConfigError(f"zenoh config {path}: expected an object {{...}} at the top, got {type(document).__name__}")
    try:
        config = zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ConfigError(f"zenoh config {path}: {_without_source_location(error)}") from None
    for key, value in FILE_DEFAULTS.items():
        if _lookup(document, key) is None:
            config.insert_json5(key, json.dumps(value))
    _check_mode_and_endpoints(mode or "peer", listen, connect)
    for key, value in (("mode", mode), ("listen/endpoints", list(listen)), ("connect/endpoints", list(connect))):
        if value:
            config.insert_json5(key, json.dumps(value))
    for key in FILE_PATH_KEYS:
        named = _lookup(document, key)
        if named is not None and not Path(named).is_file():
            raise ConfigError(f"zenoh config {path}: {key} names {named!r}, which is not a file")
    return config


def _lookup(document: dict[str, Any], key: str) -> Any:
    """The value at a `a/b/c` key path of a parsed config file, or None where it is not set."""
    value: Any = document
    for part in key.split("/"):
        if not isinstance(value, dict):
            return None
        value = value.get(part)
    return value


def _without_source_location(error: zenoh.ZError) -> str:
    """Zenoh's message without the ` at /root/.cargo/...rs:123.` of the Rust code that raised it."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?$", "", str(error).strip())


def free_endpoint() -> str:
    """A tcp endpoint on loopback whose port is free now, e.g. `tcp/127.0.0.1:40213` (tests, demo, bench).

    The port is one the OS just handed out and released: free unless another process takes it
    before the session listens on it, which on one machine's loopback is rare enough for tests.
    """
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"

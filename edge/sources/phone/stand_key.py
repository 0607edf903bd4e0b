"""The venue's stand key file (docs/qr-stands.md): 64 hex digits and a newline, readable by its owner only.

`reckon qr make` creates it (reckon/tools/qr.py); `qr read` and the phone server (edge/sources/phone/server.py)
read it. The key itself, and everything done with it, is protocol/stand_code.py, which opens no file.
"""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path

from protocol.errors import ConfigError
from protocol.stand_code import KEY_BYTES, check_key

log = logging.getLogger(__name__)

KEY_SUFFIX = ".standkey"


def key_path(venue_folder: Path | str, venue_name: str, key_file: str | None = None) -> Path:
    """Where a venue's stand key is: `key_file` if given, else `<venue file folder>/<venue name>.standkey`."""
    return Path(key_file) if key_file else Path(venue_folder) / f"{venue_name}{KEY_SUFFIX}"


def write_key(path: Path | str, key: bytes) -> None:
    """Create `path` holding `key`, mode 0600. ConfigError if the file already exists (rotating a
    key is a deliberate act: delete the old file first) or cannot be created."""
    check_key(key)
    try:
        # O_EXCL: never overwrite a key the venue's printed codes depend on.
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise ConfigError(f"{path}: a stand key file is already there; not overwriting it (to rotate the key, "
                          "move it away first and print every stand's code again)") from None
    except OSError as error:
        raise ConfigError(f"{path}: cannot create the stand key file ({error.strerror})") from None
    with os.fdopen(descriptor, "w", encoding="ascii") as file:
        file.write(key.hex() + "\n")


def load_key(path: Path | str) -> bytes:
    """The stand key in `path`. ConfigError naming the path if it is missing, unreadable, or not
    64 hex digits; a warning if others can read it."""
    try:
        text = Path(path).read_text(encoding="ascii").strip()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no stand key file there (`reckon qr make` creates one; or give --key-file)") from None
    except OSError as error:
        raise ConfigError(f"{path}: cannot read the stand key file ({error.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a stand key file (expected {2 * KEY_BYTES} hex digits, found binary)") from None
    if len(text) != 2 * KEY_BYTES or re.fullmatch(r"[0-9a-fA-F]+", text) is None:
        raise ConfigError(f"{path}: expected {2 * KEY_BYTES} hex digits (a {KEY_BYTES}-byte key), found "
                          f"{len(text)} characters{'' if re.fullmatch(r'[0-9a-fA-F]*', text) else ' that are not all hex'}")
    if os.name == "posix" and Path(path).stat().st_mode & 0o077:
        log.warning("%s: the stand key is readable by other users; chmod 600 it", path)
    return bytes.fromhex(text)

"""The phone tests' fixtures: the hall's venue file with its stand key, and a running phone server."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from support.phone import make_venue


@pytest.fixture
def venue_toml(tmp_path: Path) -> Path:
    return make_venue(tmp_path)


@pytest.fixture
def phone(venue_toml: Path):
    """A running PhoneSource on an ephemeral port, stopped at the end."""
    from edge.sources.phone.server import PhoneSource  # aiohttp is loaded only by the tests that use it
    from protocol.session import load_toml

    stop = threading.Event()
    source = PhoneSource("phone://127.0.0.1:0?http_port=0", load_toml(venue_toml), "walker", "phone", stop,
                         venue_toml=venue_toml)
    with source:
        yield source
    stop.set()

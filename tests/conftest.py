"""Fixtures shared by the whole suite. Shared code that is not a fixture is in tests/support/.

Being the rootdir conftest, this file also puts `tests/` on sys.path, so tests import
`support.*` (and never each other).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from reckon.transport.config import free_endpoint as _free_endpoint
from support.browser import CHROMIUM
from support.games import Game, Games


@pytest.fixture(scope="session")
def free_endpoint() -> Callable[[], str]:
    """`free_endpoint()`: a fresh `tcp/127.0.0.1:PORT` endpoint nothing listens on, for a Zenoh session."""
    return _free_endpoint


@pytest.fixture(scope="session")
def games(tmp_path_factory: pytest.TempPathFactory) -> Games:
    """Every simulated wheelchair game of the run by its settings, each simulated once:
    `games.path(Game(...))`, `games.summary(Game(...))`."""
    return Games(tmp_path_factory.mktemp("games"))


@pytest.fixture(scope="module")
def game(request: pytest.FixtureRequest, games: Games) -> Path:
    """The session log of the test module's `GAME = Game(players, duration_s, seed)` (support.games),
    simulated once per run however many modules name the same settings. Read it, never change it."""
    settings = getattr(request.module, "GAME", None)
    if not isinstance(settings, Game):
        raise TypeError(f"{request.module.__name__} uses the `game` fixture: it needs a module-level "
                        "GAME = Game(players, duration_s, seed) (from support.games)")
    return games.path(settings)


@pytest.fixture(scope="session")
def browser_module():
    """playwright.sync_api, with Debian's chromium to drive; the test is skipped without either
    (a browser is never downloaded)."""
    if shutil.which("chromium") is None and not Path(CHROMIUM).exists():
        pytest.skip("Debian's chromium is not installed (apt-get install -y chromium)")
    return pytest.importorskip("playwright.sync_api", reason="playwright is not installed")

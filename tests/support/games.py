"""Simulated wheelchair games for the suite, each simulated once per run (tests/conftest.py's `games`).

A test module that needs a game names it with a module-level `GAME = Game(players, duration_s, seed)`
and takes the `game` fixture (the session log's path); modules naming the same settings share
one simulation. The log is shared: read it, never write to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sim_devices.wheelchair import SimParams, SimSummary, error_free, params_with_overrides, simulate


@dataclass(frozen=True)
class Game:
    """What `sim_devices.wheelchair.simulate` is given: players, seconds, seed and `--set` overrides
    (on every error off first, if `error_free`)."""

    players: int
    duration_s: float
    seed: int
    overrides: tuple[tuple[str, str], ...] = ()
    error_free: bool = False

    def params(self) -> SimParams | None:
        """None (the simulator's defaults) unless something is changed."""
        if not self.overrides and not self.error_free:
            return None
        return params_with_overrides(dict(self.overrides), error_free() if self.error_free else None)

    def file_name(self) -> str:
        extra = "".join(f"-{key}={value}" for key, value in self.overrides) + ("-error-free" if self.error_free else "")
        return f"game-{self.players}p-{self.duration_s:g}s-seed{self.seed}{extra}.mcap"


class Games:
    """The run's simulated games by settings: each simulated on first use, then reused."""

    def __init__(self, folder: Path):
        self.folder = folder
        self._made: dict[Game, tuple[Path, SimSummary]] = {}

    def _get(self, game: Game) -> tuple[Path, SimSummary]:
        if game not in self._made:
            path = self.folder / game.file_name()
            summary = simulate(game.players, game.duration_s, game.seed, path, game.params())
            self._made[game] = (path, summary)
        return self._made[game]

    def path(self, game: Game) -> Path:
        """The game's session log."""
        return self._get(game)[0]

    def summary(self, game: Game) -> SimSummary:
        """What `simulate` returned for it."""
        return self._get(game)[1]

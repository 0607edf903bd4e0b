"""Pieces every simulated venue uses: a random small rotation, the angular rate of sampled rotations,
and writing time-ordered streams to a session log."""

from __future__ import annotations

import heapq
import math
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from protocol.errors import ConfigError
from protocol.session import Session
from protocol.session_log import SessionWriter

Item = tuple[int, int, str, Any]  # (log_time_ns, stream order, topic, message)


def small_rotation(rng: np.random.Generator, sd_deg: float) -> np.ndarray:
    """Rotation matrix for a random rotation vector with SD `sd_deg` per axis (Rodrigues)."""
    vector = np.radians(rng.normal(0.0, sd_deg, 3)) if sd_deg > 0 else np.zeros(3)
    angle = float(np.linalg.norm(vector))
    if angle < 1e-12:
        return np.eye(3)
    k = vector / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


def angular_rate(rotations: np.ndarray, rate_hz: float) -> np.ndarray:
    """Body-frame angular velocity (rad/s) of (n, 3, 3) body-to-world rotations sampled at `rate_hz`."""
    change = np.empty_like(rotations)
    change[1:-1] = rotations[2:] - rotations[:-2]
    change[0], change[-1] = 2.0 * (rotations[1] - rotations[0]), 2.0 * (rotations[-1] - rotations[-2])
    w = np.einsum("nji,njk->nik", rotations, change) * (rate_hz / 2.0)
    return np.stack([w[:, 2, 1] - w[:, 1, 2], w[:, 0, 2] - w[:, 2, 0], w[:, 1, 0] - w[:, 0, 1]], axis=1) / 2.0


def write_merged(output: Path, session: Session, sources: list[Iterator[Item]], progress: Callable[[int], None]) -> None:
    """Write streams, each in (log time, stream order), merged into one session log in that order."""
    try:
        writer = SessionWriter(output, session)
    except OSError as error:
        raise ConfigError(f"{output}: cannot write ({error.strerror})") from None
    with writer:
        for count, (log_ns, _, topic, message) in enumerate(heapq.merge(*sources, key=lambda item: item[:2])):
            writer.write(topic, message, log_ns)
            if count % 5000 == 0:
                progress(count)

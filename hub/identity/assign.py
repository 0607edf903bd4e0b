"""The assignment maths of hub/identity/engine.py: tracks x agents with "nobody" on both sides, split into
independent parts, and how much a claimed pair beats every assignment without it."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

BIG = 1e6  # a forbidden pair's cost


def components(cost: np.ndarray, nobody_cost: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The assignment splits into independent parts: a pair costing 2 x nobody_cost or more is never
    needed (its track and agent can both take "nobody" for no more), so only cheaper pairs link
    tracks and agents; each connected part (rows, columns) is solved alone, with the same optimum."""
    n_tracks, n_agents = cost.shape
    linked = cost < 2 * nobody_cost
    rows, cols = np.nonzero(linked)
    if not len(rows):
        return []
    graph = coo_matrix((np.ones(len(rows)), (rows, n_tracks + cols)), shape=(n_tracks + n_agents,) * 2)
    _, label = connected_components(graph, directed=False)
    parts = []
    for part in np.unique(label[rows]):
        members = np.flatnonzero(label == part)
        parts.append((members[members < n_tracks], members[members >= n_tracks] - n_tracks))
    return parts


def padded(cost: np.ndarray, nobody_cost: float) -> np.ndarray:
    """Tracks x agents, padded with a "nobody" column per track and a "nobody" row per agent."""
    n_tracks, n_agents = cost.shape
    size = n_tracks + n_agents
    matrix = np.full((size, size), BIG)
    matrix[:n_tracks, :n_agents] = cost
    matrix[:n_tracks, n_agents:][np.diag_indices(n_tracks)] = nobody_cost
    matrix[n_tracks:, :n_agents][np.diag_indices(n_agents)] = nobody_cost
    matrix[n_tracks:, n_agents:] = 0.0
    return matrix


def swap_bound(matrix: np.ndarray, solution: np.ndarray, row: int, col: int) -> float:
    """An upper bound on exclusion_margin, O(size): the cheapest exchange of this pair's row or column
    with another pair of the solution (a "nobody" included), which is one assignment without it."""
    others = np.arange(len(matrix))
    change = matrix[row, solution] + matrix[:, col] - matrix[row, col] - matrix[others, solution]
    change[row] = np.inf
    return float(change.min())


def exclusion_margin(matrix: np.ndarray, best: float, row: int, col: int) -> float:
    """How much worse the best assignment gets when this pair is forbidden."""
    saved = matrix[row, col]
    matrix[row, col] = BIG
    rows, cols = linear_sum_assignment(matrix)
    cost = float(matrix[rows, cols].sum())
    matrix[row, col] = saved
    return cost - best

"""The swimming paper's method on simulated sets, against the paper's own results (its Tables 1-4).

For every crawl swimmer (waist, back, head sensors) and kickboard of the default session plan,
per seed, run `edge.swim.paper.paper_length` on each length from the true push-off start to the
true wall touch (the paper cut its lengths by hand), with the raw sensor-x acceleration and the raw
sensor-z gyro, and tabulate per mounting and route the estimates' min / median / max beside the
paper's, plus the uncorrected double integral of the x acceleration (the paper's "without
correction" column: it measures how far gravity leaks into the forward axis).

    python -m sim_devices.swim.calibration --seeds 1-2            # first length of each set (the paper)
    python -m sim_devices.swim.calibration --seeds 1-2 --all-lengths

No figure is fitted here: the simulator's figures stay at their documented values (or a `--set`).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from edge.swim.paper import G, paper_length
from protocol.session import Route, route_end_heading_rad
from sim_devices.swim.params import SwimParams, params_with_overrides
from sim_devices.swim.session import plan_agents
from sim_devices.swim.simulate import simulate_set

# The paper's per-trial results (Tables 1-4): corrected estimate (m), uncorrected double integral (m).
# Kickboard: 4 trials per route (walked, pushed by hand); body mounts: 4 subjects x 2 trials, crawl.
PAPER: dict[tuple[str, str], tuple[tuple[float, ...], tuple[float, ...]]] = {
    ("kickboard", "straight"): ((25.03, 25.01, 25.01, 25.01), (964.63, 187.71, 843.07, 444.60)),
    ("kickboard", "diagonal"): ((31.98, 29.65, 29.09, 28.96), (-694.88, 571.46, 497.46, 328.55)),
    ("back", "straight"): ((25.19, 25.61, 25.97, 25.86, 25.44, 25.70, 26.03, 26.16),
                           (738.38, 807.54, -195.43, -140.04, 690.23, 566.64, 179.30, 262.09)),
    ("back", "diagonal"): ((30.20, 28.37, 26.97, 25.79, 31.48, 26.41, 29.26, 36.69),
                           (941.33, 1253.86, -20.94, -115.66, 945.97, 764.22, 289.32, 284.01)),
    ("head", "straight"): ((25.15, 25.17, 25.55, 25.36, 26.35, 28.90, 25.81, 26.22),
                           (767.60, 819.35, 1892.64, 1719.14, 1273.16, 1155.69, 1080.85, 1062.39)),
    ("head", "diagonal"): ((33.37, 26.43, 29.69, 28.22, 31.68, 33.49, 27.90, 27.31),
                           (1722.89, 1839.10, 2334.32, 2097.40, 1529.73, 1632.37, 1897.54, 1601.92)),
    ("waist", "straight"): ((25.07, 25.22, 25.04, 25.23, 25.06, 25.06, 25.03, 25.06),
                            (256.80, 232.97, 249.56, 218.34, 126.45, 180.20, 357.70, 332.73)),
    ("waist", "diagonal"): ((28.63, 27.58, 30.25, 30.05, 30.21, 28.75, 29.16, 29.45),
                            (350.14, 237.90, -338.614, -495.366, 491.98, 510.71, 434.60, 447.82)),
}
ORDER = ("kickboard", "back", "head", "waist")  # the paper's order


@dataclass
class Cell:
    """Simulated results of one mounting x route."""

    estimate_m: list[float] = field(default_factory=list)  # the paper's method, true wall times
    uncorrected_m: list[float] = field(default_factory=list)  # double integral of the raw x acceleration
    truth_m: list[float] = field(default_factory=list)  # the body centre's swum distance
    duration_s: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class Calibration:
    seeds: tuple[int, ...]
    all_lengths: bool
    cells: dict[tuple[str, str], Cell]


def uncorrected_m(time_ns: np.ndarray, forward_accel_g: np.ndarray) -> float:
    """The paper's 'without correction': x acceleration integrated twice from rest (trapezoid)."""
    dt = np.diff(time_ns) * 1e-9
    velocity = np.concatenate(([0.0], np.cumsum((forward_accel_g[1:] + forward_accel_g[:-1]) * 0.5 * G * dt)))
    return float(np.sum((velocity[1:] + velocity[:-1]) * 0.5 * dt))


def calibrate(seeds: Sequence[int] = (1, 2), swimmers: int = 4, lengths: int = 1, all_lengths: bool = False,
              params: SwimParams | None = None) -> Calibration:
    """Simulate the session plan's crawl and kickboard sets for each seed and run the paper's method."""
    params = params or SwimParams()
    cells: dict[tuple[str, str], Cell] = {key: Cell() for key in PAPER}
    for seed in seeds:
        for plan in plan_agents(seed, swimmers, ("crawl", "kick"), (Route.STRAIGHT, Route.DIAGONAL), params):
            streams, truth = simulate_set(plan.stroke, plan.route, plan.mounts, lengths, plan.seed, params,
                                          plan.agent_id, swimmer_seed=plan.swimmer_seed, start_y_m=plan.start_y_m)
            end_deg = math.degrees(route_end_heading_rad(plan.route))
            for stream in streams:
                cell = cells[(stream.mount.value, plan.route.value)]
                for index in range(len(truth.push_ns) if all_lengths else 1):
                    rows = (stream.time_ns >= truth.push_ns[index]) & (stream.time_ns <= truth.touch_ns[index])
                    time_ns, accel = stream.time_ns[rows], stream.accel_g[rows, 0]
                    estimate = paper_length(time_ns, accel, stream.gyro_dps[rows, 2], truth.pool_length_m, end_deg)
                    cell.estimate_m.append(estimate.swum_distance_m)
                    cell.uncorrected_m.append(uncorrected_m(time_ns, accel))
                    cell.truth_m.append(float(truth.swum_m[index]))
                    cell.duration_s.append(estimate.duration_s)
    return Calibration(tuple(seeds), all_lengths, cells)


def _spread(values: Sequence[float], digits: int) -> str:
    if not values:
        return "-"
    return f"{min(values):.{digits}f} / {float(np.median(values)):.{digits}f} / {max(values):.{digits}f}"


def to_table(calibration: Calibration) -> str:
    """Markdown table: per mounting x route, simulated vs paper (min / median / max)."""
    lines = ["| mounting | route | n | simulated estimate (m) | paper (m) | sim in paper's range | "
             "truth swum (m) | sim uncorrected (m) | paper uncorrected (m) | length (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for mount in ORDER:
        for route in ("straight", "diagonal"):
            cell, (paper, paper_raw) = calibration.cells[(mount, route)], PAPER[(mount, route)]
            inside = sum(min(paper) <= v <= max(paper) for v in cell.estimate_m)
            lines.append(f"| {mount} | {route} | {len(cell.estimate_m)} | {_spread(cell.estimate_m, 2)} | "
                         f"{_spread(paper, 2)} | {inside}/{len(cell.estimate_m)} | {_spread(cell.truth_m, 2)} | "
                         f"{_spread(cell.uncorrected_m, 0)} | {_spread(paper_raw, 0)} | {_spread(cell.duration_s, 1)} |")
    return "\n".join(lines)


def _seeds(text: str) -> list[int]:
    if "-" in text:
        first, last = (int(part) for part in text.split("-", 1))
        return list(range(first, last + 1))
    return [int(part) for part in text.split(",")]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sim_devices.swim.calibration", description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=_seeds, default=[1, 2], help="e.g. 1-2 (default) or 1,3")
    parser.add_argument("--swimmers", type=int, default=4)
    parser.add_argument("--lengths", type=int, default=1, help="lengths per simulated set")
    parser.add_argument("--all-lengths", action="store_true", help="score every length, not only the first")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)
    overrides = dict(pair.split("=", 1) for pair in args.set)
    calibration = calibrate(args.seeds, args.swimmers, max(args.lengths, 1), args.all_lengths,
                            params_with_overrides(overrides))
    print(to_table(calibration))
    return 0


if __name__ == "__main__":
    sys.exit(main())

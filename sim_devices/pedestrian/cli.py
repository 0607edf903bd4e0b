"""`reckon sim pedestrian`: the subcommand's arguments and its run function (registered by reckon.cli)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError


def _overrides(pairs: list[str]) -> dict[str, str]:
    result = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ReckonError(f"--set {pair!r}: expected key=value")
        result[key.strip()] = value.strip()
    return result


def run_sim_pedestrian(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.pedestrian.params import params_with_overrides
    from sim_devices.pedestrian.session import simulate_pedestrian

    params = params_with_overrides(_overrides(args.set))
    summary = simulate_pedestrian(Path(args.output), seed=args.seed, people=args.people, preset=args.preset,
                                  mount=args.mount, params=params, duration_s=args.duration,
                                  progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"))
    print(summary)
    return 0


def register(sim_kind: Any) -> None:
    """Add the `pedestrian` parser to `reckon sim`'s subparsers."""
    walk = sim_kind.add_parser("pedestrian", help="people walking a building with a phone in the hand or a pocket, "
                                                  "calibration stands with QR codes (docs/simulator-pedestrian.md)")
    walk.add_argument("--seed", type=int, default=1)
    walk.add_argument("--people", type=int, default=3, help="walkers (the paper: 3, statures 169/174/179 cm)")
    walk.add_argument("--preset", choices=["paper", "floorplan"], default="paper",
                      help="paper: the paper's 12-point corridor map and route; floorplan: an office floor with "
                           "rooms and a hall")
    walk.add_argument("--mount", choices=["hand", "pocket", "both"], default="hand",
                      help="where each walker carries a phone (both: two phones)")
    walk.add_argument("--duration", type=float, default=None, help="seconds per walker (default: the whole route)")
    walk.add_argument("-o", "--output", required=True)
    walk.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override a simulator figure (docs/simulator-pedestrian.md)")
    walk.set_defaults(run=run_sim_pedestrian)

"""`reckon calibrate`: the simulator against the paper's dead-reckoning curve (reckon/evaluation/calibration.py)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable

from reckon.cli.common import overrides


def seeds(text: str) -> list[int]:
    """"1-5" or "1,3,7" -> seeds."""
    try:
        if "-" in text:
            first, last = (int(part) for part in text.split("-", 1))
            return list(range(first, last + 1))
        return [int(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected seeds like 1-5 or 1,3,7") from None


def run_calibrate(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    """Simulate the default game for each seed and compare the paper's dead reckoning with the paper."""
    from reckon.evaluation.calibration import calibrate_sessions, to_json, to_table, write_plot
    from sim_devices.wheelchair import params_with_overrides, simulate

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = params_with_overrides(overrides(args.set))
    sessions = {}
    for seed in args.seeds:
        sessions[seed] = out / f"game-seed{seed}.mcap"
        progress(f"simulating seed {seed}")
        simulate(args.players, args.duration, seed, sessions[seed], params,
                 progress=lambda fraction, seed=seed: progress(f"simulating seed {seed}: {100 * fraction:.0f} %"))
    calibration = calibrate_sessions(sessions, progress)
    print(json.dumps(to_json(calibration), indent=1) if args.json else to_table(calibration))
    print(f"wrote {write_plot(calibration, out / 'calibration.png')}", file=sys.stderr)
    return 0


def register(sub: Any) -> None:
    cal = sub.add_parser("calibrate", help="the simulator against the paper's dead-reckoning curve, over seeds")
    cal.add_argument("--seeds", type=seeds, default=[1, 2, 3, 4, 5], help="e.g. 1-5 (default) or 1,3")
    cal.add_argument("--players", type=int, default=10)
    cal.add_argument("--duration", type=float, default=317.0)
    cal.add_argument("--out", default="out/calibration", help="folder for the sessions and calibration.png")
    cal.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="simulator parameter override")
    cal.add_argument("--json", action="store_true")
    cal.set_defaults(run=run_calibrate)

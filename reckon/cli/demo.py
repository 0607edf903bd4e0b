"""`reckon demo`: simulate a game, play it live through edges and the hub, then score it (reckon/tools/demo.py)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable

from reckon.cli.evaluate import run_eval
from reckon.cli.sim import run_sim


def run_demo(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    """Simulate a game, play it live through edges and the hub, score it; then the offline comparison."""
    from reckon.tools.demo import run_live

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    game = out / "game.mcap"
    sim_args = argparse.Namespace(players=args.players, duration=args.duration, seed=args.seed, output=game, set=[],
                                  world=0)
    print(f"simulating {args.players} chairs for {args.duration:.0f} s (seed {args.seed}) -> {game}", file=sys.stderr)
    run_sim(sim_args, progress)
    print(f"\nlive: {args.players} edge processes and a hub over Zenoh on loopback, {args.speed:g} x real time",
          file=sys.stderr)
    result = run_live(game, out, args.speed, args.lag, lambda text: print(text + "\n", file=sys.stderr, flush=True))
    corrections = {}
    for kinds in result.corrections.values():
        for kind, count in kinds.items():
            corrections[kind] = corrections.get(kind, 0) + count
    print(f"live pipeline ({result.game_s:.0f} s game in {result.wall_s:.0f} s wall, recorded in {out / 'hub.mcap'}): "
          f"mean error live {result.mean_error_m['live']:.2f} m, refined {result.mean_error_m['refined']:.2f} m; "
          f"corrections {', '.join(f'{k} {v}' for k, v in sorted(corrections.items())) or 'none'}")
    print()
    eval_args = argparse.Namespace(session=[game], json=False, plots=out / "plots", identity_scaling=False,
                                   worlds=None, room_worlds=None)
    return run_eval(eval_args, progress)


def register(sub: Any) -> None:
    demo = sub.add_parser("demo", help="simulate the demo venue, evaluate, print the table, write plots")
    demo.add_argument("--players", type=int, default=10)
    demo.add_argument("--duration", type=float, default=317.0)
    demo.add_argument("--seed", type=int, default=1)
    demo.add_argument("--out", default="out/demo")
    demo.add_argument("--speed", type=float, default=3.0,
                      help="times real time (default 3; a 2-core machine keeps up to about 6, docs/benchmarks.md)")
    demo.add_argument("--lag", type=float, default=30.0, metavar="S", help="the hub's refined-track lag (default 30 s)")
    demo.set_defaults(run=run_demo)

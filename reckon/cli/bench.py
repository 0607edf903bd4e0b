"""`reckon bench [pipeline|load|soak]`: throughput, latency and memory here (reckon/bench/)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Callable


def run_bench_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    if args.suite == "load":
        from reckon.bench.load import format_load, run_load

        result = run_load(Path(args.out) / "load", agents=args.agents, rate_hz=args.rate, duration_s=args.duration,
                          seed=args.seed, progress=progress, hubs=args.hubs, record=args.record)
        print(json.dumps(result, indent=1) if args.json else format_load(result))
        return 0
    if args.suite == "soak":
        from reckon.bench.soak import PLAYERS, format_soak, run_soak

        result = run_soak(Path(args.out) / "soak", hours=args.hours, players=args.players or PLAYERS, seed=args.seed,
                          progress=progress)
        print(json.dumps(result, indent=1) if args.json else format_soak(result))
        return 0
    from reckon.bench.compare import compare, format_comparison, load_baseline
    from reckon.bench.pipeline import format_table, run_bench

    baseline = load_baseline(args.compare) if args.compare else None  # a bad file fails before the minute of bench
    result = run_bench(Path(args.out), players=args.players or 10, duration_s=args.duration, seed=args.seed,
                       progress=progress, latency_players=args.latency_players)
    rows = compare(result, baseline) if baseline is not None else []
    if args.json:
        print(json.dumps({**result, "comparison": rows} if baseline is not None else result, indent=1))
    else:
        print(format_table(result))
        if baseline is not None:
            print(format_comparison(rows, args.compare))
    return 1 if any(row["worse"] for row in rows) else 0


def register(sub: Any) -> None:
    bench = sub.add_parser("bench", help="measure the edge estimator, the live pipeline, latency and memory here")
    bench.add_argument("suite", nargs="?", choices=("pipeline", "load", "soak"), default="pipeline",
                       help="pipeline (default): edge, pipeline, latency, memory; load: one hub with --agents chairs "
                       "at --rate Hz; soak: --hours of a game through edges and a hub, RSS sampled")
    bench.add_argument("--players", type=int, help="chairs (default 10; soak 2)")
    bench.add_argument("--duration", type=float, default=60.0,
                       help="game seconds of the unpaced run; load: seconds of load (default 60)")
    bench.add_argument("--agents", type=int, default=500, help="load: simulated chairs (default 500)")
    bench.add_argument("--hubs", type=int, default=1,
                       help="load: hubs, the courts sharded among them, each its own venue (default 1)")
    bench.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="load: poses per chair a second (default 50)")
    bench.add_argument("--record", action="store_true",
                       help="load: each hub records every input and output (-o), as the installed hub does")
    bench.add_argument("--hours", type=float, default=1.0, help="soak: hours of game replayed (default 1)")
    bench.add_argument("--seed", type=int, default=1)
    bench.add_argument("--latency-players", type=int, metavar="N", help="chairs in the paced latency run (default: --players)")
    bench.add_argument("--out", default="out/bench", help="folder for the games, the hub's recordings and the process logs")
    bench.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    bench.add_argument("--compare", metavar="BASE.json", help="pipeline: every figure beside a saved `--json` run's, "
                       "as a ratio; exit status 1 if any is more than 25 %% worse")
    bench.set_defaults(run=run_bench_command)

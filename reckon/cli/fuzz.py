"""`reckon fuzz`: the push decoders against mutated frames (reckon/tools/fuzz.py)."""

from __future__ import annotations

import argparse
from typing import Any, Callable


def run_fuzz_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.tools.fuzz import run_atheris, run_fuzz

    if args.engine == "atheris":
        return run_atheris(args.decoder, args.frames)
    results = run_fuzz(args.decoder, args.frames, args.seed)
    for result in results:
        print(result)
    return 1 if any(r.crashes for r in results) else 0


def register(sub: Any) -> None:
    fuzz = sub.add_parser("fuzz", help="the device decoders against mutated frames: crashes and frames recovered")
    fuzz.add_argument("--frames", type=int, default=1_000_000, help="frames per decoder, intact and mutated")
    fuzz.add_argument("--decoder", choices=("tsnd", "ximu3", "ble", "all"), default="all")
    fuzz.add_argument("--seed", type=int, default=1)
    fuzz.add_argument("--engine", choices=("random", "atheris"), default="random",
                      help="atheris: libFuzzer's coverage-guided inputs (needs the optional atheris package)")
    fuzz.set_defaults(run=run_fuzz_command)

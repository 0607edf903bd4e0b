"""The one command-line entry point: `reckon sim|import|qr|eval|replay|record|edge|hub|export|doctor|
calibrate|demo|bench|fuzz`, one module of this package per command (replay and record: `bus.py`).

Each module's `register(sub)` adds its parser, whose `run(args, progress)` handler parses the
arguments into plain values and calls the code that does the work, importing it only then: building
the parser imports no optional library, so `reckon edge` on an edge loads nothing of the
evaluation. Errors a user can cause (a bad file, a wrong key, an extra not installed) print one
line naming the problem and exit with status 2.
"""

from __future__ import annotations

import argparse
import logging
import sys

from protocol.errors import ReckonError
from reckon.cli import (bench, bus, calibrate, demo, doctor, edge, evaluate, export, fuzz, hub, importing, qr,
                        sim)
from reckon.cli.common import Progress

# In the order `reckon --help` lists them.
COMMANDS = (sim, importing, qr, evaluate, bus, edge, hub, export, doctor, calibrate, demo, bench, fuzz)

# The install extra (pyproject.toml) each command needs beyond the core dependencies; a command
# not named here needs only the core. `doctor` checks devices with the edge's own sources.
EXTRAS = {"sim": "eval", "import": "eval", "eval": "eval", "export": "eval", "calibrate": "eval", "demo": "eval",
          "bench": "eval", "qr": "qr", "edge": "edge", "hub": "hub", "doctor": "edge"}
# The top-level modules of the extras' distributions: a missing one means an extra is not installed.
OPTIONAL_MODULES = frozenset({"serial", "bleak", "numba", "llvmlite", "imufusion", "scipy", "aiohttp", "cryptography",
                              "zxingcpp", "PIL", "shapely", "segno", "matplotlib", "motmetrics", "foxglove",
                              "pygeomag", "setuptools"})


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="reckon", description="Multi-agent inertial positioning for sports venues.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    progress = Progress(enabled=not args.quiet)
    try:
        return args.run(args, progress)
    except ReckonError as error:
        print(f"reckon: error: {error}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as error:
        extra = EXTRAS.get(args.command)
        if extra is None or (error.name or "").partition(".")[0] not in OPTIONAL_MODULES:
            raise  # not an extra's library: a broken install or a bug, worth its traceback
        print(f"reckon {args.command} needs the [{extra}] extra: pip install 'reckon[{extra}]' "
              f"({error.name} is not installed)", file=sys.stderr)
        return 2
    except OSError as error:  # a path the user gave that cannot be read or written
        if isinstance(error, BrokenPipeError):  # `reckon eval ... | head`: the reader left
            sys.stderr.close()
            return 0
        print(f"reckon: error: {error.filename or ''}: {error.strerror or error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

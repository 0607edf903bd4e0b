"""`reckon export foxglove`: a session log with Foxglove scene channels added (reckon/tools/foxglove.py)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable


def run_export(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.tools.foxglove import export_foxglove

    print(export_foxglove(Path(args.input), Path(args.output), progress=progress))
    return 0


def register(sub: Any) -> None:
    export = sub.add_parser("export", help="convert a session log for another tool")
    export_kind = export.add_subparsers(dest="format", required=True)
    fox = export_kind.add_parser("foxglove", help="add Foxglove 3D scene channels (court, beacons, agents) to a copy "
                                 "of a session log (docs/court-view.md)")
    fox.add_argument("input", metavar="IN.mcap")
    fox.add_argument("-o", "--output", required=True, metavar="OUT.mcap")
    fox.set_defaults(run=run_export)

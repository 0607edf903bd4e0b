"""`reckon qr make|read`: the venue's calibration stands' QR codes (reckon/tools/qr.py, docs/qr-stands.md).

The parser is here, not beside the drawing code, so that building the CLI imports no image library.
"""

from __future__ import annotations

import argparse
from typing import Any, Callable

from edge.sources.phone.stand_key import KEY_SUFFIX

DEFAULT_OUTPUT = "out/qr"


def run_make(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.tools import qr

    return qr.run_make(args, progress)


def run_read(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.tools import qr

    return qr.run_read(args, progress)


def register(sub: Any) -> None:
    qr = sub.add_parser("qr", help="calibration stands' QR codes: print them, check photos of them "
                                   "(docs/qr-stands.md)")
    commands = qr.add_subparsers(dest="qr_command", required=True)
    key_help = (f"the venue's stand key (default: <venue file folder>/<venue name>{KEY_SUFFIX}; "
                "`make` creates it on first use)")
    make = commands.add_parser("make", help="a printable PNG and SVG for every stand of the venue")
    make.add_argument("venue", metavar="VENUE.toml", help="the venue file, with [[venue.stands]]")
    make.add_argument("-o", "--output", default=DEFAULT_OUTPUT, metavar="DIR", help=f"default {DEFAULT_OUTPUT}")
    make.add_argument("--key-file", metavar="F", help=key_help)
    make.set_defaults(run=run_make)
    read = commands.add_parser("read", help="decode stand codes in images and check them against the venue")
    read.add_argument("images", nargs="+", metavar="IMAGE", help="PNG, JPEG, ... (a photo or a made code)")
    read.add_argument("--venue", required=True, metavar="VENUE.toml")
    read.add_argument("--key-file", metavar="F", help=key_help)
    read.set_defaults(run=run_read)

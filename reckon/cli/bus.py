"""The Zenoh options every bus command takes (`--listen`, `--connect`, `--mode`, `--zenoh-config`),
and the two commands that only move a venue's messages: `reckon replay` and `reckon record`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable

from reckon.cli.common import stop_on_signals


def bus_options(command: argparse.ArgumentParser) -> None:
    command.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="e.g. tcp/127.0.0.1:7447")
    command.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
    command.add_argument("--mode", choices=["peer", "client", "router"], help="default: peer, or the --zenoh-config file's")
    command.add_argument("--zenoh-config", metavar="FILE.json5",
                         help="a Zenoh config file (router, TLS, credentials: deploy/zenoh/); "
                              "--listen/--connect/--mode override it")


def bus_config(args: argparse.Namespace, default_role: str):
    """Zenoh config from --zenoh-config and --listen/--connect/--mode; by default the embedded loopback endpoint."""
    from reckon.transport.bus import DEFAULT_ENDPOINT, zenoh_config, zenoh_config_from_file

    listen, connect = list(args.listen), list(args.connect)
    if args.zenoh_config:  # the file's endpoints unless the command line gives its own
        return zenoh_config_from_file(args.zenoh_config, mode=args.mode, listen=listen, connect=connect)
    if not listen and not connect:
        (listen if default_role == "listen" else connect).append(DEFAULT_ENDPOINT)
    return zenoh_config(mode=args.mode or "peer", listen=listen, connect=connect)


def run_replay(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.transport.replay import replay

    summary = replay(Path(args.session), bus_config(args, "connect"), speed=args.speed,
                     progress=lambda state: progress(str(state)), wait_for=args.wait_for,
                     wait_timeout_s=args.wait_timeout, stop=stop_on_signals())
    print(summary)
    return 0


def run_record(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from protocol.session import load_toml
    from reckon.transport.record import record

    description = load_toml(Path(args.session)) if args.session else None
    summary = record(bus_config(args, "listen"), args.venue, Path(args.output), stop_on_signals(),
                     description=description, until_end=args.until_end,
                     progress=lambda count: progress(f"recorded {count} messages"))
    print(summary)
    return 0


def register(sub: Any) -> None:
    rep = sub.add_parser("replay", help="publish a session log over Zenoh as if its devices were live")
    rep.add_argument("session")
    rep.add_argument("--speed", type=float, default=1.0, help="times real time; 0 = as fast as the bus takes it")
    rep.add_argument("--wait-for", type=int, default=0, metavar="N", help="wait for N hubs/recorders first")
    rep.add_argument("--wait-timeout", type=float, default=60.0, metavar="S")
    bus_options(rep)
    rep.set_defaults(run=run_replay)

    rec = sub.add_parser("record", help="record every message of a venue from Zenoh into a session log")
    rec.add_argument("--venue", required=True)
    rec.add_argument("-o", "--output", required=True)
    rec.add_argument("--session", metavar="VENUE.toml", help="the session description, if no source announces it")
    rec.add_argument("--until-end", action="store_true", help="stop when the source says the session is over")
    bus_options(rec)
    rec.set_defaults(run=run_record)

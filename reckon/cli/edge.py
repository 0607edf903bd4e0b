"""`reckon edge`: one agent's edge process (reckon/processes/edge.py)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError
from reckon.cli.bus import bus_config, bus_options
from reckon.cli.common import stop_on_signals


def run_edge_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.processes.edge import open_sources, run_edge

    stop = stop_on_signals()
    session, source = open_sources(args.source, args.agent, args.speed, stop,
                                   Path(args.venue) if args.venue else None, start_at=args.start_at)
    if hasattr(source, "addresses"):  # a phone: the person needs the page's address
        print(source.addresses(), file=sys.stderr, flush=True)
    summary = run_edge(bus_config(args, "connect"), session, args.agent, source, stop, pose_rate_hz=args.pose_rate,
                       wait_for=args.wait_for, wait_timeout_s=args.wait_timeout,
                       progress=lambda state: progress(str(state)), spool=Path(args.spool) if args.spool else None,
                       spool_limit_bytes=spool_limit_bytes(args.spool_limit_mb))
    print(summary)
    return 0


def spool_limit_bytes(megabytes: float) -> int:
    if not megabytes > 0:
        raise ReckonError(f"--spool-limit-mb {megabytes:g}: must be more than 0 (MiB)")
    return int(megabytes * 1024 * 1024)


def register(sub: Any) -> None:
    edge = sub.add_parser("edge", help="one agent's edge process (a chair, a swimmer or a pedestrian): its devices' samples in, poses and events out over Zenoh")
    edge.add_argument("--agent", required=True)
    edge.add_argument("--source", required=True, action="append", metavar="URL",
                      help="mcap://SESSION.mcap (this agent's sensors), or SENSOR=serial://PORT?baud=N or "
                           "SENSOR=ble://ADDRESS once per sensor, plus RECEIVER=ble://scan for beacons")
    edge.add_argument("--venue", metavar="VENUE.toml", help="session description (needed with serial and BLE sources)")
    edge.add_argument("--speed", type=float, default=1.0, help="replay sources: times real time; 0 = as fast as possible")
    edge.add_argument("--start-at", type=float, metavar="UNIX_S",
                      help="replay sources: wall-clock time of the log's first message (keeps several edges in step)")
    edge.add_argument("--pose-rate", type=float, default=50.0, metavar="HZ", help="pose messages per second (default 50)")
    edge.add_argument("--wait-for", type=int, default=0, metavar="N", help="wait for N hubs/recorders first")
    edge.add_argument("--wait-timeout", type=float, default=60.0, metavar="S")
    edge.add_argument("--spool", metavar="DIR", help="keep messages here while no hub is up, replay them in order "
                      "when one is (docs/faults.md; default: no spool)")
    edge.add_argument("--spool-limit-mb", type=float, default=512.0, metavar="N",
                      help="the spool's size limit in MiB; past it new messages are refused and counted (default 512)")
    bus_options(edge)
    edge.set_defaults(run=run_edge_command)

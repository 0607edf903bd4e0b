"""`reckon hub`: the venue's hub process (reckon/processes/hub.py), with the live court view."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError
from protocol.messages import Track
from protocol.session import AgentKind
from reckon.cli.bus import bus_config, bus_options
from reckon.cli.common import stop_on_signals


def run_hub_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from hub.chair.hub import HubSettings
    from protocol.session_log import session_description  # not reckon.processes.edge's: that loads the edge's filters
    from reckon.processes.hub import run_hub

    session = session_description(Path(args.venue))
    try:
        settings = HubSettings(lag_s=args.lag, pose_rate_hz=args.pose_rate,
                               corrections=frozenset(args.corrections.split(",")) if args.corrections else frozenset())
    except ValueError as error:
        raise ReckonError(f"reckon hub: {error}") from None
    walkers = {agent.id for agent in session.agents if agent.kind is AgentKind.PEDESTRIAN}
    latest: dict[str, str] = {}

    def show(output: Any) -> None:  # pedestrians' map-matched positions, as they walk
        if output.DESCRIPTOR.name == "EstimatedPose" and output.agent_id in walkers and output.track == Track.LIVE:
            latest[output.agent_id] = f"{output.agent_id} x {output.x_m:.1f} m y {output.y_m:.1f} m"
            progress("; ".join(latest[agent_id] for agent_id in sorted(latest)))

    view = None
    if args.view:  # before the hub starts: a taken port fails at once
        from reckon.web.court_view import CourtView, parse_view_address

        view = CourtView(session, *parse_view_address(args.view))
        print(f"court view: open {view.url} in a browser", file=sys.stderr, flush=True)

    def on_output(output: Any) -> None:
        if walkers:
            show(output)
        if view is not None:
            view.on_output(output)

    try:
        summary = run_hub(bus_config(args, "listen"), session, stop_on_signals(), settings,
                          Path(args.output) if args.output else None, on_output=on_output if walkers or view else None,
                          on_input=view.on_input if view else None, on_bus=view.attach if view else None,
                          state=Path(args.state) if args.state else None)
    finally:
        if view is not None:
            view.close()
    print(summary)
    return 0


def register(sub: Any) -> None:
    hub = sub.add_parser("hub", help="the venue's hub: every agent in, corrected poses and corrections out over Zenoh")
    hub.add_argument("--venue", required=True, metavar="VENUE.toml", help="session description (or a session log)")
    hub.add_argument("-o", "--output", metavar="FILE.mcap", help="record every input and output here")
    hub.add_argument("--lag", type=float, default=30.0, metavar="S", help="refined track lag (default 30 s)")
    hub.add_argument("--pose-rate", type=float, default=50.0, metavar="HZ", help="the edges' pose rate (default 50)")
    hub.add_argument("--state", metavar="FILE", help="checkpoint the hub here every 2 s and restore from it on start "
                     "(needs -o; the restarted hub records to hub.1.mcap, ...; docs/faults.md)")
    hub.add_argument("--corrections", default="beacon,collision,fix",
                     help="comma-separated: beacon, collision, fix (default all; empty for none)")
    hub.add_argument("--view", metavar="HOST:PORT",
                     help="serve the live court view here, e.g. 127.0.0.1:8080 (docs/court-view.md; default off)")
    bus_options(hub)
    hub.set_defaults(run=run_hub_command)

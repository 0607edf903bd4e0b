"""`reckon eval`: the estimators over a session log, scored against its truth (reckon/evaluation/)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError
from protocol.session import AgentKind


def run_eval(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from protocol.session_log import read_session
    from reckon.evaluation import pdr_eval
    from reckon.evaluation.evaluate import evaluate_data
    from reckon.evaluation.report import to_json, to_table
    from reckon.evaluation.swim_eval import evaluate_swim, is_swim_session

    if args.room_worlds is not None:
        if args.session or args.worlds is not None:
            raise ReckonError("reckon eval: give session logs, --worlds or --room-worlds, one of them")
        return _run_room_worlds(args, progress)
    if args.worlds is not None:
        if args.session:
            raise ReckonError("reckon eval: give session logs or --worlds, not both")
        return _run_worlds(args, progress)
    if not args.session:
        raise ReckonError("reckon eval: give a session log (or --worlds A-B)")
    paths = [Path(p) for p in args.session]
    sessions = [(read_session(p), p) for p in paths]
    if all(pdr_eval.is_pedestrian_session(data) for data, _ in sessions):
        pedestrians = pdr_eval.evaluate_pedestrians(sessions, progress)
        print(json.dumps(pdr_eval.to_json(pedestrians), indent=1) if args.json else pdr_eval.to_table(pedestrians))
        return 0
    if len(sessions) > 1:
        raise ReckonError(f"reckon eval: several sessions are pooled only for pedestrian walks; "
                          f"{paths[1]} and the others need one eval each")
    data, path = sessions[0]
    if is_swim_session(data):
        from reckon.evaluation import swim_eval

        swim = evaluate_swim(data, path, progress)
        print(json.dumps(swim_eval.to_json(swim), indent=1) if args.json else swim_eval.to_table(swim))
        return 0
    from reckon.evaluation import identity_eval

    identity = identity_eval.evaluate_identity(data, path, progress) if identity_eval.has_cameras(data) else None
    if identity is not None and args.identity_scaling:
        identity.rows += identity_eval.scaling(progress=progress)
    chairs = all(agent.kind is AgentKind.WHEELCHAIR for agent in data.session.agents)
    report = evaluate_data(data, path, progress) if chairs or identity is None else None
    if args.json:
        out = to_json(report) if report is not None else {"session": str(path)}
        if identity is not None:
            out["identity"] = identity_eval.to_json(identity)
        print(json.dumps(out, indent=1))
    else:
        print("\n\n".join(part for part in (to_table(report) if report is not None else "",
                                               identity_eval.to_table(identity) if identity is not None else "") if part))
    if report is None:
        return 0
    if args.plots:
        from reckon.evaluation.plots import write_plots

        for path in write_plots(report, Path(args.plots), report.court_m):
            print(f"wrote {path}", file=sys.stderr)
    return 0


def _run_worlds(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.evaluation import worlds_eval
    from sim_devices.wheelchair.worlds import parse_worlds

    worlds = parse_worlds(args.worlds)
    if args.duration is None:
        args.duration = 317.0  # the paper's game length in the chair simulator
    command = (f"reckon eval --worlds {args.worlds} --seed {args.seed} --players {args.players} "
               f"--duration {args.duration:g}")
    progress(f"{len(worlds)} worlds, {args.players} chairs for {args.duration:g} s each")
    results = worlds_eval.evaluate_worlds(worlds, args.seed, args.players, args.duration, args.jobs, progress)
    summary = worlds_eval.summarise(results)
    print(json.dumps({"command": command, **summary}, indent=1) if args.json
          else worlds_eval.to_table(summary, command))
    return 0


def _run_room_worlds(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.evaluation import room_worlds_eval
    from sim_devices.room.session import PAPER_DURATION_S
    from sim_devices.wheelchair.worlds import parse_worlds

    worlds = parse_worlds(args.room_worlds)
    duration = args.duration if args.duration is not None else PAPER_DURATION_S
    command = (f"reckon eval --room-worlds {args.room_worlds} --seed {args.seed} --people {args.people} "
               f"--duration {duration:g}")
    progress(f"{len(worlds)} room worlds, {args.people} wearers for {duration:g} s each")
    results = room_worlds_eval.evaluate_room_worlds(worlds, args.seed, args.people, duration, args.jobs, progress)
    summary = room_worlds_eval.summarise(results)
    print(json.dumps({"command": command, **summary}, indent=1) if args.json
          else room_worlds_eval.to_table(summary, command))
    return 0


def register(sub: Any) -> None:
    ev = sub.add_parser("eval", help="run the estimators over a session and score them against truth")
    ev.add_argument("session", nargs="*", help="a session log; pedestrian walks: several, pooled")
    ev.add_argument("--worlds", metavar="A-B", help="instead of a log: simulate one wheelchair game in each of "
                    "worlds A..B (docs/simulator-worlds.md) and report the spread over worlds")
    ev.add_argument("--seed", type=int, default=1, help="with --worlds: the game's motion seed")
    ev.add_argument("--players", type=int, default=10, help="with --worlds: chairs per game")
    ev.add_argument("--room-worlds", metavar="A-B", help="instead of a log: simulate the camera-identity room in "
                    "each of room worlds A..B (docs/simulator-room.md) and report the spread of time correct")
    ev.add_argument("--people", type=int, default=3, help="with --room-worlds: wearers per room")
    ev.add_argument("--duration", type=float, help="with --worlds or --room-worlds: seconds per game (317) or "
                    "room (297)")
    ev.add_argument("--jobs", type=int, help="with --worlds: worker processes (default: one per core)")
    ev.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    ev.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    ev.add_argument("--identity-scaling", action="store_true",
                    help="with camera tracks: also time both identity methods at 3, 6, 10, 20 and 50 wearers "
                         "(simulated rooms, about 2 min)")
    ev.set_defaults(run=run_eval)

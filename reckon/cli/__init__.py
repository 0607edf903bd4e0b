"""The one command-line entry point: `reckon sim|import|eval|demo`.

Each subcommand parses its arguments into plain values and calls one `run_*` function; errors a
user can cause (a bad file, a wrong key) print one line naming the problem and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError
from protocol.messages import Track
from protocol.session import AgentKind

log = logging.getLogger("reckon")


class Progress:
    """Progress lines on stderr, at most one per `every_s` unless forced."""

    def __init__(self, enabled: bool, every_s: float = 1.0):
        self.enabled, self.every_s, self.last = enabled, every_s, 0.0
        self.start = time.monotonic()

    def __call__(self, text: str) -> None:
        now = time.monotonic()
        if self.enabled and now - self.last >= self.every_s:
            self.last = now
            print(f"[{now - self.start:6.1f} s] {text}", file=sys.stderr, flush=True)


def _overrides(pairs: list[str]) -> dict[str, str]:
    result = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ReckonError(f"--set {pair!r}: expected key=value")
        result[key.strip()] = value.strip()
    return result


def _key_value(text: str) -> str:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY=VALUE")
    return text


def run_sim(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.wheelchair import params_with_overrides, simulate

    params = params_with_overrides(_overrides(args.set))
    summary = simulate(args.players, args.duration, args.seed, Path(args.output), params,
                       progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"),
                       camera=getattr(args, "camera", False))
    print(summary)
    return 0


def run_sim_swim(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.swim import params_with_overrides, simulate_swim

    params = params_with_overrides(_overrides(args.set))
    summary = simulate_swim(Path(args.output), seed=args.seed, swimmers=args.swimmers, lengths=args.lengths,
                            params=params, progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"))
    print(summary)
    return 0


def run_sim_room(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.room import params_with_overrides, simulate_room

    params = params_with_overrides(_overrides(args.set))
    summary = simulate_room(Path(args.output), seed=args.seed, people=args.people, duration_s=args.duration,
                            params=params, camera=not args.no_camera,
                            progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"))
    print(summary)
    return 0


def run_sim_pedestrian(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.pedestrian.params import params_with_overrides
    from sim_devices.pedestrian.session import simulate_pedestrian

    params = params_with_overrides(_overrides(args.set))
    summary = simulate_pedestrian(Path(args.output), seed=args.seed, people=args.people, preset=args.preset,
                                  mount=args.mount, params=params, duration_s=args.duration,
                                  progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"))
    print(summary)
    return 0


def run_import(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    if args.format == "ilc":
        from reckon.importers.ilc_session import import_walks

        for walk in import_walks([Path(p) for p in args.folder], Path(args.output)):
            print(walk)
        return 0
    if len(args.folder) != 1:
        raise ReckonError(f"reckon import {args.format}: one PATH expected, got {len(args.folder)}")
    args.folder = args.folder[0]
    if args.format == "tracks":
        from reckon.importers.tracks_csv import import_tracks_csv

        print(import_tracks_csv(Path(args.folder), Path(args.output),
                                session_toml=Path(args.session) if args.session else None,
                                into=Path(args.into) if args.into else None, camera_id=args.camera_id,
                                fps=args.fps, start_s=args.start, position_sd_m=args.position_sd))
        return 0
    if args.format == "csv":
        from reckon.importers.csv_folder import import_csv_folder

        report = import_csv_folder(Path(args.folder), Path(args.output))
    elif args.format == "tsnd":
        from reckon.importers.tsnd_csv import DEFAULT_VENUE, import_tsnd_csv

        venue = args.venue or DEFAULT_VENUE
        toml = Path(venue) if venue.lower().endswith(".toml") else None  # a session description, else a name
        report = import_tsnd_csv(Path(args.folder), Path(args.output), venue_toml=toml, venue=venue, agent_id=args.agent)
    else:
        from reckon.importers.ngimu import import_ngimu_folder

        mounts = dict(pair.split("=", 1) for pair in args.mount) if args.mount else None
        spin_axes = dict(pair.split("=", 1) for pair in args.spin_axis) if args.spin_axis else None
        report = import_ngimu_folder(Path(args.folder), Path(args.output), mounts=mounts, spin_axes=spin_axes,
                                     wheel_diameter_m=args.wheel_diameter_m, agent_id=args.agent or "chair",
                                     venue=args.venue or "lab")
    print(report)
    return 0


def run_eval(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from protocol.session_log import read_session
    from reckon.evaluation.evaluate import evaluate_data
    from reckon.evaluation.report import to_json, to_table
    from reckon.evaluation.swim_eval import evaluate_swim, is_swim_session

    from reckon.evaluation import pdr_eval

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


def _seeds(text: str) -> list[int]:
    """"1-5" or "1,3,7" -> seeds."""
    try:
        if "-" in text:
            first, last = (int(part) for part in text.split("-", 1))
            return list(range(first, last + 1))
        return [int(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected seeds like 1-5 or 1,3,7") from None


def run_calibrate(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    """Simulate the default game for each seed and compare the paper's dead reckoning with the paper."""
    from reckon.evaluation.calibration import calibrate_sessions, to_json, to_table, write_plot
    from sim_devices.wheelchair import params_with_overrides, simulate

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = params_with_overrides(_overrides(args.set))
    sessions = {}
    for seed in args.seeds:
        sessions[seed] = out / f"game-seed{seed}.mcap"
        progress(f"simulating seed {seed}")
        simulate(args.players, args.duration, seed, sessions[seed], params,
                 progress=lambda fraction, seed=seed: progress(f"simulating seed {seed}: {100 * fraction:.0f} %"))
    calibration = calibrate_sessions(sessions, progress)
    print(json.dumps(to_json(calibration), indent=1) if args.json else to_table(calibration))
    print(f"wrote {write_plot(calibration, out / 'calibration.png')}", file=sys.stderr)
    return 0


def _bus_config(args: argparse.Namespace, default_role: str):
    """Zenoh config from --zenoh-config and --listen/--connect/--mode; by default the embedded loopback endpoint."""
    from reckon.transport.bus import DEFAULT_ENDPOINT, zenoh_config, zenoh_config_from_file

    listen, connect = list(args.listen), list(args.connect)
    if args.zenoh_config:  # the file's endpoints unless the command line gives its own
        return zenoh_config_from_file(args.zenoh_config, mode=args.mode, listen=listen, connect=connect)
    if not listen and not connect:
        (listen if default_role == "listen" else connect).append(DEFAULT_ENDPOINT)
    return zenoh_config(mode=args.mode or "peer", listen=listen, connect=connect)


def _stop_on_signals():
    """An Event set by Ctrl-C or SIGTERM, so a recorder can finish its file."""
    import signal
    import threading

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def run_replay(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.transport.replay import replay

    summary = replay(Path(args.session), _bus_config(args, "connect"), speed=args.speed,
                     progress=lambda state: progress(str(state)), wait_for=args.wait_for,
                     wait_timeout_s=args.wait_timeout, stop=_stop_on_signals())
    print(summary)
    return 0


def run_record(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from protocol.session import load_toml
    from reckon.transport.record import record

    description = load_toml(Path(args.session)) if args.session else None
    summary = record(_bus_config(args, "listen"), args.venue, Path(args.output), _stop_on_signals(),
                     description=description, until_end=args.until_end,
                     progress=lambda count: progress(f"recorded {count} messages"))
    print(summary)
    return 0


def run_edge_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.processes.edge import open_sources, run_edge

    stop = _stop_on_signals()
    session, source = open_sources(args.source, args.agent, args.speed, stop,
                                   Path(args.venue) if args.venue else None, start_at=args.start_at)
    if hasattr(source, "addresses"):  # a phone: the person needs the page's address
        print(source.addresses(), file=sys.stderr, flush=True)
    summary = run_edge(_bus_config(args, "connect"), session, args.agent, source, stop, pose_rate_hz=args.pose_rate,
                       wait_for=args.wait_for, wait_timeout_s=args.wait_timeout,
                       progress=lambda state: progress(str(state)), spool=Path(args.spool) if args.spool else None,
                       spool_limit_bytes=_spool_limit_bytes(args.spool_limit_mb))
    print(summary)
    return 0


def _spool_limit_bytes(megabytes: float) -> int:
    if not megabytes > 0:
        raise ReckonError(f"--spool-limit-mb {megabytes:g}: must be more than 0 (MiB)")
    return int(megabytes * 1024 * 1024)


def run_hub_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from hub.chair.hub import HubSettings
    from reckon.processes.edge import session_description
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
        summary = run_hub(_bus_config(args, "listen"), session, _stop_on_signals(), settings,
                          Path(args.output) if args.output else None, on_output=on_output if walkers or view else None,
                          on_input=view.on_input if view else None, on_bus=view.attach if view else None,
                          state=Path(args.state) if args.state else None)
    finally:
        if view is not None:
            view.close()
    print(summary)
    return 0


def run_export(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.tools.foxglove import export_foxglove

    print(export_foxglove(Path(args.input), Path(args.output), progress=progress))
    return 0


def run_demo(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    """Simulate a game, play it live through edges and the hub, score it; then the offline comparison."""
    from reckon.tools.demo import run_live

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    game = out / "game.mcap"
    sim_args = argparse.Namespace(players=args.players, duration=args.duration, seed=args.seed, output=game, set=[])
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
    eval_args = argparse.Namespace(session=[game], json=False, plots=out / "plots", identity_scaling=False)
    return run_eval(eval_args, progress)


def run_bench_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    if args.suite == "load":
        from reckon.bench.load import format_load, run_load

        result = run_load(Path(args.out) / "load", agents=args.agents, rate_hz=args.rate, duration_s=args.duration,
                          seed=args.seed, progress=progress)
        print(json.dumps(result, indent=1) if args.json else format_load(result))
        return 0
    if args.suite == "soak":
        from reckon.bench.soak import PLAYERS, format_soak, run_soak

        result = run_soak(Path(args.out) / "soak", hours=args.hours, players=args.players or PLAYERS, seed=args.seed,
                          progress=progress)
        print(json.dumps(result, indent=1) if args.json else format_soak(result))
        return 0
    from reckon.bench.pipeline import format_table, run_bench

    result = run_bench(Path(args.out), players=args.players or 10, duration_s=args.duration, seed=args.seed,
                       progress=progress, latency_players=args.latency_players)
    print(json.dumps(result, indent=1) if args.json else format_table(result))
    return 0


def run_fuzz_command(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from reckon.tools.fuzz import run_atheris, run_fuzz

    if args.engine == "atheris":
        return run_atheris(args.decoder, args.frames)
    results = run_fuzz(args.decoder, args.frames, args.seed)
    for result in results:
        print(result)
    return 1 if any(r.crashes for r in results) else 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="reckon", description="Multi-agent inertial positioning for sports venues.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("sim", help="simulate a venue into a session log (MCAP)")
    sim_kind = sim.add_subparsers(dest="kind", required=True)
    chairs = sim_kind.add_parser("wheelchair", help="a wheelchair-basketball game on a 28 x 15 m court")
    chairs.add_argument("--players", type=int, default=10)
    chairs.add_argument("--duration", type=float, default=317.0, help="seconds (the paper's game: 317)")
    chairs.add_argument("--seed", type=int, default=1)
    chairs.add_argument("-o", "--output", required=True)
    chairs.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a simulator parameter (docs/simulator.md)")
    chairs.add_argument("--camera", action="store_true",
                        help="add a simulated court tracker's anonymous tracks and their truth labels, two referees "
                             "included (docs/simulator-camera.md)")
    chairs.set_defaults(run=run_sim)
    swim = sim_kind.add_parser("swim", help="swimmers and kickboards in a 25 x 18 m pool, straight and diagonal "
                                            "lengths (docs/simulator-swim.md)")
    swim.add_argument("--seed", type=int, default=1)
    swim.add_argument("--swimmers", type=int, default=4, help="crawl swimmers and kickboards per route (the paper: 4)")
    swim.add_argument("--lengths", type=int, default=4, help="lengths per set")
    swim.add_argument("-o", "--output", required=True)
    swim.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override a simulator figure (docs/simulator-swim.md)")
    swim.set_defaults(run=run_sim_swim)
    room = sim_kind.add_parser("room", help="the camera-identity paper's room: people walking with a waist sensor, "
                                            "seen by a stereo head tracker (docs/simulator-room.md)")
    room.add_argument("--seed", type=int, default=1)
    room.add_argument("--people", type=int, default=3, help="wearers (the paper: 3); the room grows with them")
    room.add_argument("--duration", type=float, default=297.0, help="seconds (the paper's recording: 297)")
    room.add_argument("--no-camera", action="store_true", help="leave the tracker's frames out")
    room.add_argument("-o", "--output", required=True)
    room.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override a simulator figure (docs/simulator-room.md)")
    room.set_defaults(run=run_sim_room)
    walk = sim_kind.add_parser("pedestrian", help="people walking a building with a phone in the hand or a pocket, "
                                                  "calibration stands with QR codes (docs/simulator-pedestrian.md)")
    walk.add_argument("--seed", type=int, default=1)
    walk.add_argument("--people", type=int, default=3, help="walkers (the paper: 3, statures 169/174/179 cm)")
    walk.add_argument("--preset", choices=["paper", "floorplan"], default="paper",
                      help="paper: the paper's 12-point corridor map and route; floorplan: an office floor with "
                           "rooms and a hall")
    walk.add_argument("--mount", choices=["hand", "pocket", "both"], default="hand",
                      help="where each walker carries a phone (both: two phones)")
    walk.add_argument("--duration", type=float, default=None, help="seconds per walker (default: the whole route)")
    walk.add_argument("-o", "--output", required=True)
    walk.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override a simulator figure (docs/simulator-pedestrian.md)")
    walk.set_defaults(run=run_sim_pedestrian)

    imp = sub.add_parser("import", help="convert recorded logs into a session log")
    imp.add_argument("format", choices=["csv", "ngimu", "tsnd", "tracks", "ilc"],
                     help="csv: docs/csv-import.md; ngimu: x-io NGIMU folders; tsnd: an ATR TSND121/151 CSV log; "
                          "tracks: a camera tracker's tracks, MOTChallenge-style CSV; ilc: Indoor Location "
                          "Competition 2.0 phone walks (docs/pdr-estimator.md)")
    imp.add_argument("folder", metavar="PATH", nargs="+",
                     help="the folder (csv, ngimu), the CSV file (tsnd, tracks), or walk files (ilc: several)")
    imp.add_argument("-o", "--output", required=True,
                     help="the session log; ilc with several walks: a folder for one log per walk")
    ngimu = imp.add_argument_group("ngimu and tsnd options")
    ngimu.add_argument("--wheel-diameter-m", type=float, default=0.62, help="wheel diameter (default 0.62 m)")
    ngimu.add_argument("--agent", help="agent id (ngimu: default chair; tsnd: default the swimmer)")
    ngimu.add_argument("--venue", help="venue name (ngimu: default lab; tsnd: default pool), or for tsnd a "
                                       "session description VENUE.toml")
    ngimu.add_argument("--mount", action="append", default=[], type=_key_value, metavar="DEVICE=MOUNT",
                       help="device folder, serial or sensor id = seat|left_wheel|right_wheel (default: from names)")
    ngimu.add_argument("--spin-axis", action="append", default=[], type=_key_value, metavar="WHEEL=AXIS",
                       help="e.g. left_wheel=+y (default: found from the data, assuming mostly forward pushing)")
    tracks = imp.add_argument_group("tracks options (docs/csv-import.md, camera tracks)")
    tracks.add_argument("--session", metavar="SESSION.toml", help="the session description for a new log")
    tracks.add_argument("--into", metavar="LOG.mcap",
                        help="or: an existing session log; -o gets its messages plus the tracks (-o may be LOG)")
    tracks.add_argument("--camera-id", default="cam1", help="camera id (default cam1)")
    tracks.add_argument("--fps", type=float, help="frame rate, when the file has no time column")
    tracks.add_argument("--start", metavar="UNIX_S", help="time of frame 1 in seconds, when the file has no time column")
    tracks.add_argument("--position-sd", type=float, metavar="M",
                        help="the tracker's 1-sigma position error per axis (default 0.1 m, with a warning)")
    imp.set_defaults(run=run_import)

    from reckon.tools import qr

    qr.register(sub)

    ev = sub.add_parser("eval", help="run the estimators over a session and score them against truth")
    ev.add_argument("session", nargs="+", help="a session log; pedestrian walks: several, pooled")
    ev.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    ev.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    ev.add_argument("--identity-scaling", action="store_true",
                    help="with camera tracks: also time both identity methods at 3, 6, 10, 20 and 50 wearers "
                         "(simulated rooms, about 2 min)")
    ev.set_defaults(run=run_eval)

    def bus_options(command: argparse.ArgumentParser) -> None:
        command.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="e.g. tcp/127.0.0.1:7447")
        command.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
        command.add_argument("--mode", choices=["peer", "client", "router"], help="default: peer, or the --zenoh-config file's")
        command.add_argument("--zenoh-config", metavar="FILE.json5",
                             help="a Zenoh config file (router, TLS, credentials: deploy/zenoh/); "
                                  "--listen/--connect/--mode override it")

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

    edge = sub.add_parser("edge", help="one chair's edge process: sensor messages in, poses out over Zenoh")
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

    export = sub.add_parser("export", help="convert a session log for another tool")
    export_kind = export.add_subparsers(dest="format", required=True)
    fox = export_kind.add_parser("foxglove", help="add Foxglove 3D scene channels (court, beacons, agents) to a copy "
                                 "of a session log (docs/court-view.md)")
    fox.add_argument("input", metavar="IN.mcap")
    fox.add_argument("-o", "--output", required=True, metavar="OUT.mcap")
    fox.set_defaults(run=run_export)

    from reckon.tools import doctor

    doctor.register(sub, bus_options, _bus_config)

    cal = sub.add_parser("calibrate", help="the simulator against the paper's dead-reckoning curve, over seeds")
    cal.add_argument("--seeds", type=_seeds, default=[1, 2, 3, 4, 5], help="e.g. 1-5 (default) or 1,3")
    cal.add_argument("--players", type=int, default=10)
    cal.add_argument("--duration", type=float, default=317.0)
    cal.add_argument("--out", default="out/calibration", help="folder for the sessions and calibration.png")
    cal.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="simulator parameter override")
    cal.add_argument("--json", action="store_true")
    cal.set_defaults(run=run_calibrate)

    demo = sub.add_parser("demo", help="simulate the demo venue, evaluate, print the table, write plots")
    demo.add_argument("--players", type=int, default=10)
    demo.add_argument("--duration", type=float, default=317.0)
    demo.add_argument("--seed", type=int, default=1)
    demo.add_argument("--out", default="out/demo")
    demo.add_argument("--speed", type=float, default=3.0,
                      help="times real time (default 3; a 2-core machine keeps up to about 6, docs/benchmarks.md)")
    demo.add_argument("--lag", type=float, default=30.0, metavar="S", help="the hub's refined-track lag (default 30 s)")
    demo.set_defaults(run=run_demo)
    bench = sub.add_parser("bench", help="measure the edge estimator, the live pipeline, latency and memory here")
    bench.add_argument("suite", nargs="?", choices=("pipeline", "load", "soak"), default="pipeline",
                       help="pipeline (default): edge, pipeline, latency, memory; load: one hub with --agents chairs "
                       "at --rate Hz; soak: --hours of a game through edges and a hub, RSS sampled")
    bench.add_argument("--players", type=int, help="chairs (default 10; soak 2)")
    bench.add_argument("--duration", type=float, default=60.0,
                       help="game seconds of the unpaced run; load: seconds of load (default 60)")
    bench.add_argument("--agents", type=int, default=500, help="load: simulated chairs (default 500)")
    bench.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="load: poses per chair a second (default 50)")
    bench.add_argument("--hours", type=float, default=1.0, help="soak: hours of game replayed (default 1)")
    bench.add_argument("--seed", type=int, default=1)
    bench.add_argument("--latency-players", type=int, metavar="N", help="chairs in the paced latency run (default: --players)")
    bench.add_argument("--out", default="out/bench", help="folder for the games, the hub's recordings and the process logs")
    bench.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    bench.set_defaults(run=run_bench_command)
    fuzz = sub.add_parser("fuzz", help="the device decoders against mutated frames: crashes and frames recovered")
    fuzz.add_argument("--frames", type=int, default=1_000_000, help="frames per decoder, intact and mutated")
    fuzz.add_argument("--decoder", choices=("tsnd", "ximu3", "ble", "all"), default="all")
    fuzz.add_argument("--seed", type=int, default=1)
    fuzz.add_argument("--engine", choices=("random", "atheris"), default="random",
                      help="atheris: libFuzzer's coverage-guided inputs (needs the optional atheris package)")
    fuzz.set_defaults(run=run_fuzz_command)
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

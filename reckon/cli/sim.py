"""`reckon sim wheelchair|swim|room|pedestrian`: simulated venues into session logs (sim_devices/)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable

from reckon.cli.common import overrides


def run_sim(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.wheelchair import params_with_overrides, simulate
    from sim_devices.wheelchair.worlds import world_params

    params = params_with_overrides(overrides(args.set), world_params(args.world))
    summary = simulate(args.players, args.duration, args.seed, Path(args.output), params,
                       progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"),
                       camera=getattr(args, "camera", False), world=args.world)
    print(summary)
    return 0


def run_sim_swim(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.swim import params_with_overrides, simulate_swim

    params = params_with_overrides(overrides(args.set))
    summary = simulate_swim(Path(args.output), seed=args.seed, swimmers=args.swimmers, lengths=args.lengths,
                            params=params, progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"))
    print(summary)
    return 0


def run_sim_room(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.room import params_with_overrides, simulate_room
    from sim_devices.room.worlds import room_world

    base, tracker = room_world(args.world)
    params = params_with_overrides(overrides(args.set), base)
    summary = simulate_room(Path(args.output), seed=args.seed, people=args.people, duration_s=args.duration,
                            params=params, camera=not args.no_camera, tracker=tracker, world=args.world,
                            progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"))
    print(summary)
    return 0


def run_sim_pedestrian(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    from sim_devices.pedestrian.params import params_with_overrides
    from sim_devices.pedestrian.session import simulate_pedestrian

    params = params_with_overrides(overrides(args.set))
    summary = simulate_pedestrian(Path(args.output), seed=args.seed, people=args.people, preset=args.preset,
                                  mount=args.mount, params=params, duration_s=args.duration,
                                  progress=lambda fraction: progress(f"simulating: {100 * fraction:.0f} %"),
                                  beacons=args.beacons, barometer=args.barometer)
    print(summary)
    return 0


def _seed_output_set(parser: argparse.ArgumentParser, doc: str) -> None:
    """What every simulator takes: its seed, the session log to write, and figure overrides."""
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-o", "--output", required=True)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help=f"override a simulator figure ({doc})")


def register(sub: Any) -> None:
    sim = sub.add_parser("sim", help="simulate a venue into a session log (MCAP)")
    sim_kind = sim.add_subparsers(dest="kind", required=True)
    chairs = sim_kind.add_parser("wheelchair", help="a wheelchair-basketball game on a 28 x 15 m court")
    chairs.add_argument("--players", type=int, default=10)
    chairs.add_argument("--duration", type=float, default=317.0, help="seconds (the paper's game: 317)")
    _seed_output_set(chairs, "docs/simulator.md")
    chairs.add_argument("--world", type=int, default=0,
                        help="draw every error source from its documented range, world K independent of --seed; "
                             "0: the simulator's defaults (docs/simulator-worlds.md)")
    chairs.add_argument("--camera", action="store_true",
                        help="add a simulated court tracker's anonymous tracks and their truth labels, two referees "
                             "included (docs/simulator-camera.md)")
    chairs.set_defaults(run=run_sim)
    swim = sim_kind.add_parser("swim", help="swimmers and kickboards in a 25 x 18 m pool, straight and diagonal "
                                            "lengths (docs/simulator-swim.md)")
    swim.add_argument("--swimmers", type=int, default=4, help="crawl swimmers and kickboards per route (the paper: 4)")
    swim.add_argument("--lengths", type=int, default=4, help="lengths per set")
    _seed_output_set(swim, "docs/simulator-swim.md")
    swim.set_defaults(run=run_sim_swim)
    room = sim_kind.add_parser("room", help="the camera-identity paper's room: people walking with a waist sensor, "
                                            "seen by a stereo head tracker (docs/simulator-room.md)")
    room.add_argument("--people", type=int, default=3, help="wearers (the paper: 3); the room grows with them")
    room.add_argument("--duration", type=float, default=297.0, help="seconds (the paper's recording: 297)")
    room.add_argument("--no-camera", action="store_true", help="leave the tracker's frames out")
    room.add_argument("--world", type=int, default=0,
                      help="draw the tracker's errors and the people from their documented ranges, room world K "
                           "independent of --seed; 0: today's room (docs/simulator-room.md)")
    _seed_output_set(room, "docs/simulator-room.md")
    room.set_defaults(run=run_sim_room)
    walk = sim_kind.add_parser("pedestrian", help="people walking a building with a phone in the hand or a pocket, "
                                                  "calibration stands with QR codes (docs/simulator-pedestrian.md)")
    walk.add_argument("--people", type=int, default=3, help="walkers (the paper: 3, statures 169/174/179 cm)")
    walk.add_argument("--preset", choices=["paper", "floorplan", "floors"], default="paper",
                      help="paper: the paper's 12-point corridor map and route; floorplan: an office floor with "
                           "rooms and a hall; floors: that office on two floors with a staircase, a barometer and "
                           "BLE beacons")
    walk.add_argument("--beacons", type=int, default=None, metavar="N",
                      help="BLE beacons per floor (default: 6 on preset floors, none elsewhere)")
    walk.add_argument("--barometer", action=argparse.BooleanOptionalAction, default=None,
                      help="phone barometers (default: on for preset floors only)")
    walk.add_argument("--mount", choices=["hand", "pocket", "both"], default="hand",
                      help="where each walker carries a phone (both: two phones)")
    walk.add_argument("--duration", type=float, default=None, help="seconds per walker (default: the whole route)")
    _seed_output_set(walk, "docs/simulator-pedestrian.md")
    walk.set_defaults(run=run_sim_pedestrian)

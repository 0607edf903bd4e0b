"""`reckon import csv|ngimu|tsnd|tracks|ilc|getsensordata`: recorded logs into session logs (reckon/importers/)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError
from reckon.cli.common import key_value


def run_import(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    if args.format == "ilc":
        from reckon.importers.ilc_session import import_walks

        for walk in import_walks([Path(p) for p in args.folder], Path(args.output)):
            print(walk)
        return 0
    if len(args.folder) != 1:
        raise ReckonError(f"reckon import {args.format}: one PATH expected, got {len(args.folder)}")
    args.folder = args.folder[0]
    if args.format == "getsensordata":
        from reckon.importers.geo import parse_lat_lon
        from reckon.importers.getsensordata_session import import_getsensordata

        origin = parse_lat_lon(args.origin, "--origin") if args.origin else None
        print(import_getsensordata(Path(args.folder), Path(args.output),
                                   beacons_csv=Path(args.beacons) if args.beacons else None, origin=origin))
        return 0
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


def register(sub: Any) -> None:
    imp = sub.add_parser("import", help="convert recorded logs into a session log")
    imp.add_argument("format", choices=["csv", "ngimu", "tsnd", "tracks", "ilc", "getsensordata"],
                     help="csv: docs/csv-import.md; ngimu: x-io NGIMU folders; tsnd: an ATR TSND121/151 CSV log; "
                          "tracks: a camera tracker's tracks, MOTChallenge-style CSV; ilc: Indoor Location "
                          "Competition 2.0 phone walks (docs/pdr-estimator.md); getsensordata: a GetSensorData "
                          "app log, IPIN's smartphone tracks (docs/getsensordata-import.md)")
    imp.add_argument("folder", metavar="PATH", nargs="+",
                     help="the folder (csv, ngimu), the CSV file (tsnd, tracks), the log (getsensordata), or walk "
                          "files (ilc: several)")
    imp.add_argument("-o", "--output", required=True,
                     help="the session log; ilc with several walks: a folder for one log per walk")
    ngimu = imp.add_argument_group("ngimu and tsnd options")
    ngimu.add_argument("--wheel-diameter-m", type=float, default=0.62, help="wheel diameter (default 0.62 m)")
    ngimu.add_argument("--agent", help="agent id (ngimu: default chair; tsnd: default the swimmer)")
    ngimu.add_argument("--venue", help="venue name (ngimu: default lab; tsnd: default pool), or for tsnd a "
                                       "session description VENUE.toml")
    ngimu.add_argument("--mount", action="append", default=[], type=key_value, metavar="DEVICE=MOUNT",
                       help="device folder, serial or sensor id = seat|left_wheel|right_wheel (default: from names)")
    ngimu.add_argument("--spin-axis", action="append", default=[], type=key_value, metavar="WHEEL=AXIS",
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
    gsd = imp.add_argument_group("getsensordata options (docs/getsensordata-import.md)")
    gsd.add_argument("--beacons", metavar="BEACONS.csv",
                     help="the venue's beacons: CSV id,lat,lon,floor, id ibeacon:<uuid>:<major>:<minor> or "
                          "eddystone:<namespace>:<instance> (or eddystone:<instance>)")
    gsd.add_argument("--origin", metavar="LAT,LON",
                     help="the local frame's tangent point, decimal degrees (default: the first POSI point)")
    imp.set_defaults(run=run_import)

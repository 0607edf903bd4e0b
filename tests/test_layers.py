"""Cores stay pure: estimators, decoders and hub rules import no I/O library and no clock."""

from __future__ import annotations

import json
import subprocess
import sys

CORES = ["edge.chair_estimator", "edge.chair_merger", "edge.wheel", "edge.paper_dr", "edge.impacts", "edge.mag_heading",
         "edge.mounting", "edge.decoders", "hub.paper_rules", "hub.chair_corrections", "hub.track_paper",
         "protocol.messages", "protocol.stand_code", "edge.pdr", "edge.pdr_steps", "edge.pdr_magnetic",
         "edge.pdr_paper", "edge.pdr_edge", "hub.pedestrian_hub", "hub.map_particles", "hub.map_snap_paper",
         "hub.walkable",
         "protocol.keys", "protocol.session", "protocol.bus"]
FORBIDDEN = {"zenoh", "serial", "bleak", "mcap", "mcap_protobuf", "asyncio", "socket", "matplotlib"}


def test_cores_import_no_io():
    code = ("import importlib, json, sys\n"
            f"for name in {CORES!r}: importlib.import_module(name)\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    loaded = set(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout))
    assert not loaded & FORBIDDEN, f"a core pulled in {sorted(loaded & FORBIDDEN)}"

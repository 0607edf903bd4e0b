"""Cores stay pure: estimators, decoders and hub rules import no I/O library and no clock."""

from __future__ import annotations

import json
import subprocess
import sys

CORES = ["edge.chair.estimator", "edge.chair.merger", "edge.chair.paper.wheel", "edge.chair.paper.dr", "edge.chair.paper.impacts", "edge.chair.paper.mag_heading",
         "edge.mounting", "edge.decoders", "hub.chair.paper", "hub.chair.corrections", "hub.identity.paper.search",
         "protocol.messages", "protocol.stand_code", "edge.pedestrian.estimator", "edge.pedestrian.steps", "edge.pedestrian.magnetic",
         "edge.pedestrian.paper", "edge.pedestrian.edge", "hub.pedestrian.hub", "hub.pedestrian.particles", "hub.pedestrian.paper",
         "hub.pedestrian.walkable",
         "protocol.keys", "protocol.session", "protocol.bus"]
FORBIDDEN = {"zenoh", "serial", "bleak", "mcap", "mcap_protobuf", "asyncio", "socket", "matplotlib"}


def test_cores_import_no_io():
    code = ("import importlib, json, sys\n"
            f"for name in {CORES!r}: importlib.import_module(name)\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    loaded = set(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout))
    assert not loaded & FORBIDDEN, f"a core pulled in {sorted(loaded & FORBIDDEN)}"

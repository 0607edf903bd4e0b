"""A chair's merger and filter compiled ahead of time (reckon/kernels.py): the same bits as the
just-in-time kernels, an edge process without numba, and a clear fallback where it cannot be built."""

from __future__ import annotations

import json
import logging
import subprocess
import sys

import numpy as np
import pytest

from edge.chair.edge import ChairEdge
from edge.chair.kernel import just_in_time
from protocol import keys
from protocol.session_log import LogMessages, read_description
from reckon import kernels
from support.games import Game

GAME = Game(players=2, duration_s=30.0, seed=7)
# what a chair's edge process must not load: the just-in-time compiler and the other kinds' libraries
NOT_IN_A_CHAIR_EDGE = ("numba", "llvmlite", "scipy", "imufusion")
EDGE_RSS_LIMIT_MB = 100  # issue 18's bound for an edge process


def outputs(game, agent, kernels) -> list[tuple]:
    """Every pose, impact and field reading of one chair's edge over the game, as plain numbers."""
    edge = ChairEdge(agent, kernels=kernels)
    batches = [m for _, topic, m in LogMessages(game, lambda topic, name: name == "ImuBatch"
                                                and keys.parse(topic)[1] == agent.id)]
    made = [out for batch in batches for out in edge.push(batch)] + edge.flush()
    return [(out.DESCRIPTOR.name, out.timestamp_ns,
             *((out.x_m, out.y_m, out.heading_rad, *out.covariance) if out.DESCRIPTOR.name == "EstimatedPose"
               else (out.x_m, out.y_m, out.offset_rad, out.variance_rad2) if out.DESCRIPTOR.name == "FieldReading"
               else (out.peak_g, out.forward_g, out.left_g)))
            for out in made]


def test_the_ahead_of_time_kernel_gives_the_just_in_time_kernels_bits(game):
    compiled, loaded = kernels.chair_kernels()
    assert loaded == "ahead-of-time"  # this machine has a C compiler: the fallback would hide a broken build
    assert kernels.module_path(kernels.build_key()).exists()
    for agent in read_description(game).agents:
        ahead = outputs(game, agent, compiled)
        assert len(ahead) > 1000 and ahead == outputs(game, agent, just_in_time())


def test_the_kernel_refuses_arrays_of_the_wrong_layout():
    run_batch = kernels.chair_kernels()[0].run_batch
    with pytest.raises(ValueError, match="not as pack_settings"):
        run_batch(np.zeros(3), np.zeros(3), np.zeros(0, dtype=np.int64), np.zeros((0, 11)))


def test_a_chair_edge_process_loads_no_compiler_and_no_other_kinds_libraries(game):
    kernels.chair_kernels()  # built before the child looks for it
    code = f"""
import json, re, sys, threading
from reckon.processes.edge import EDGES, open_sources
session, source = open_sources(["mcap://{game}"], "chair01", 0.0, threading.Event())
agent = session.agent("chair01")
edge = EDGES[agent.kind](agent, session, 50.0)
poses = sum(out.DESCRIPTOR.name == "EstimatedPose" for message in source if message.DESCRIPTOR.name == "ImuBatch"
            for out in edge.push(message))
peak_kb = int(re.search(r"VmHWM:\\s+(\\d+)", open("/proc/self/status").read()).group(1))  # ru_maxrss outlives exec
print(json.dumps({{"poses": poses, "rss_mb": peak_kb / 1024,
                  "loaded": sorted(set({NOT_IN_A_CHAIR_EDGE!r}) & set(sys.modules))}}))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)
    assert found["poses"] > 1000
    assert found["loaded"] == []
    assert found["rss_mb"] <= EDGE_RSS_LIMIT_MB


def test_where_it_cannot_be_built_the_kernel_is_compiled_in_process_and_the_log_says_why(
        monkeypatch, tmp_path, caplog):
    monkeypatch.setattr(kernels, "_loaded", {})
    monkeypatch.setattr(kernels, "build_key", lambda: "0" * 16)  # a source no module was built for
    monkeypatch.setattr(kernels, "DIRECTORY", tmp_path / "not-there")  # and nowhere to build it
    with caplog.at_level(logging.WARNING, logger="reckon.kernels"):
        compiled, loaded = kernels.chair_kernels()
    assert loaded == "just-in-time" and compiled == just_in_time()
    assert "cannot build in" in caplog.text and str(tmp_path / "not-there") in caplog.text

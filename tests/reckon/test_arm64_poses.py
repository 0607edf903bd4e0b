"""deploy/arm64-poses.py, the arm64 check's verdict (deploy/arm64-check.sh runs it inside the
emulated root): live poses counted per agent of a real session log, status 1 when an agent has none."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from protocol import keys, messages
from protocol.session import load_toml
from protocol.session_log import SessionWriter
from support.venue import agent_table, write_venue

SCRIPT = Path(__file__).resolve().parents[2] / "deploy" / "arm64-poses.py"


def verdict(session: Path, recording: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), str(session), str(recording)], capture_output=True, text=True,
                          cwd=SCRIPT.parents[1])


def test_live_poses_are_counted_per_agent_and_an_agent_without_any_fails(tmp_path):
    session = load_toml(write_venue(tmp_path / "venue.toml", "court", agents=[agent_table("chair01"),
                                                                             agent_table("chair02")]))
    log, recording = tmp_path / "session.mcap", tmp_path / "hub.mcap"
    with SessionWriter(log, session):
        pass
    with SessionWriter(recording, session) as writer:
        for i in range(3):
            pose = messages.new("EstimatedPose", timestamp_ns=i + 1, agent_id="chair01", track=messages.Track.LIVE)
            writer.write(keys.pose("court", "chair01", "live"), pose)
        writer.write(keys.pose("court", "chair02", "edge"), messages.new("EstimatedPose", timestamp_ns=1,
                                                                         agent_id="chair02"))
    done = verdict(log, recording)
    assert (done.returncode, done.stdout.strip()) == (1, "chair01=3 chair02=0")
    with SessionWriter(recording, session) as writer:
        for agent in ("chair01", "chair02"):
            writer.write(keys.pose("court", agent, "live"), messages.new("EstimatedPose", timestamp_ns=1,
                                                                         agent_id=agent))
    done = verdict(log, recording)
    assert (done.returncode, done.stdout.strip()) == (0, "chair01=1 chair02=1")


def test_an_unreadable_file_is_status_2_naming_it(tmp_path):
    done = verdict(tmp_path / "missing.mcap", tmp_path / "hub.mcap")
    assert done.returncode == 2 and "missing.mcap" in done.stderr


def test_the_check_script_parses():
    assert subprocess.run(["bash", "-n", str(SCRIPT.with_name("arm64-check.sh"))]).returncode == 0

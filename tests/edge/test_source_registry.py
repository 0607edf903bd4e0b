"""The source registry (edge/sources/registry.py): every scheme found by name, an unknown one
refused naming it and the known ones, one kind of source per edge, and each scheme's `check`
(what `reckon doctor` runs) against real parts: a session log, a missing port, a Bluetooth
adapter folder, a TCP port."""

from __future__ import annotations

import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from edge.sources import registry
from edge.sources.registry import CheckRequest, Level, open_sources, scheme
from protocol import keys, messages
from protocol.errors import ConfigError
from protocol.session import load_toml
from protocol.session_log import SessionWriter
from support.venue import agent_table, sensor_table, write_venue


@pytest.fixture
def venue(tmp_path: Path) -> Path:
    return write_venue(tmp_path / "venue.toml", "court", beacons=[{"id": "goal-a", "x_m": 1.575, "y_m": 7.5}],
                       agents=[agent_table("chair1", sensors=[sensor_table("seat", "seat")])])


def test_every_registered_scheme_is_found_by_its_name():
    for name in registry.SOURCE_MODULES:
        found = scheme(name)
        assert found.name == name and callable(found.open) and callable(found.check)


def test_an_unknown_scheme_names_itself_and_the_known_ones():
    with pytest.raises(ConfigError, match=r"--source 'seat=tcp://x': unknown scheme 'tcp' "
                                          r"\(known: mcap, serial, ble, phone\)"):
        open_sources(["seat=tcp://x"], "chair1", 0.0, threading.Event())
    with pytest.raises(ConfigError, match=r"unknown scheme 'none' \(known: mcap, serial, ble, phone\)"):
        scheme("")


def test_a_scheme_whose_library_is_missing_says_which(monkeypatch):
    monkeypatch.setitem(registry.SOURCE_MODULES, "can", "no_such_can_bus_library")
    with pytest.raises(ConfigError, match="can:// sources need the no_such_can_bus_library package"):
        scheme("can", "seat=can://0")


def test_schemes_are_not_mixed_on_one_edge(venue):
    with pytest.raises(ConfigError, match="'seat=ble://AA:BB:CC:DD:EE:FF': serial and ble sources cannot be mixed"):
        open_sources(["seat=serial:///dev/null", "seat=ble://AA:BB:CC:DD:EE:FF"], "chair1", 0.0, threading.Event(),
                     venue)
    with pytest.raises(ConfigError, match="'seat=tcp://x': unknown scheme 'tcp'"):  # the unknown one first
        open_sources(["seat=serial:///dev/null", "seat=tcp://x"], "chair1", 0.0, threading.Event(), venue)


def test_a_live_source_needs_a_sensor_id_and_the_venue(venue):
    with pytest.raises(ConfigError, match="'serial:///dev/null': no sensor id in front"):
        open_sources(["serial:///dev/null"], "chair1", 0.0, threading.Event(), venue)
    with pytest.raises(ConfigError, match="chair1 has no sensor 'hat'"):
        open_sources(["hat=serial:///dev/null"], "chair1", 0.0, threading.Event(), venue)


def log_file(tmp_path: Path, venue: Path) -> Path:
    path = tmp_path / "game.mcap"
    time_ns = np.arange(20, dtype=np.int64) * 5_000_000
    with SessionWriter(path, load_toml(venue)) as writer:
        writer.write(keys.imu("court", "chair1", "seat"),
                     messages.imu_batch("chair1", "seat", 0, time_ns, np.zeros((20, 3)), np.zeros((20, 3)), None))
    return path


def test_mcap_check_and_open(tmp_path, venue):
    path = log_file(tmp_path, venue)
    [good] = scheme("mcap").check(CheckRequest(f"mcap://{path}", agent="chair1"))
    assert good.level is Level.OK and "1 messages, 1 agents" in good.message
    [other] = scheme("mcap").check(CheckRequest(f"mcap://{path}", agent="chair9"))
    assert other.level is Level.FAIL and "no messages of agent 'chair9'" in other.message
    session, source = open_sources([f"mcap://{path}"], "chair1", 0.0, threading.Event())
    assert session.venue.name == "court" and [m.sensor_id for m in source] == ["seat"]


def test_serial_check_of_a_missing_port():
    [finding] = scheme("serial").check(CheckRequest("serial:///dev/ttyNOPE9", "seat"))
    assert finding.level is Level.FAIL and finding.message == "/dev/ttyNOPE9 does not exist"


def test_ble_check_looks_for_an_adapter_and_a_scan_for_identities(tmp_path, venue):
    sysfs = tmp_path / "bluetooth"
    sysfs.mkdir()
    request = CheckRequest("ble://AA:BB:CC:DD:EE:FF", "seat", load_toml(venue), venue, bluetooth_sysfs=sysfs)
    [none] = scheme("ble").check(request)
    assert none.level is Level.WARN and "no Bluetooth adapter" in none.message
    (sysfs / "hci0").mkdir()
    [found] = scheme("ble").check(request)
    assert found.level is Level.OK and "hci0" in found.message
    scan = CheckRequest("ble://scan", "rx", load_toml(venue), venue, bluetooth_sysfs=sysfs)
    [refused] = scheme("ble").check(scan)
    assert refused.level is Level.FAIL and "identity" in refused.message
    assert not scheme("ble").sensor("ble://scan") and scheme("ble").sensor("ble://AA:BB:CC:DD:EE:FF")


def test_phone_check_of_a_busy_and_a_free_port(tmp_path, venue):
    with socket.create_server(("127.0.0.1", 0)) as busy:
        port = busy.getsockname()[1]
        [in_use] = scheme("phone").check(CheckRequest(f"phone://127.0.0.1:{port}", "seat", load_toml(venue), venue))
    assert in_use.level is Level.FAIL and f"port {port} is in use" in in_use.message
    [free] = scheme("phone").check(CheckRequest(f"phone://127.0.0.1:{port}", "seat", load_toml(venue), venue))
    assert free.level is Level.WARN and "no certificate yet" in free.message

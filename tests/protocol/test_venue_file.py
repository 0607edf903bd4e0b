"""The venue file: every key the loader accepts is documented in docs/session-format.md (and no
documented key is unknown to it), and wrong values are refused at load naming the key's path.
Also the other settings a venue operator types (`--set`, device URLs, hub corrections) refuse
unknown keys by name."""

from __future__ import annotations

import copy
import dataclasses
import importlib
import math
import re
from pathlib import Path

import pytest

from protocol.errors import ConfigError
from protocol.session import Agent, Beacon, MapPoint, Sensor, Session, Stand, Venue, load_toml, session_from_dict
from support.venue import agent_table, sensor_table, write_venue

DOC = Path(__file__).resolve().parents[2] / "docs" / "session-format.md"
HEADING = re.compile(r"^#{2,3} (.+)$")


def loader_keys(cls: type) -> set[str]:
    """The keys the loader accepts for a table: its dataclass's fields (what `_check_keys` allows)."""
    return {f.name for f in dataclasses.fields(cls)}


# Section heading in the doc -> the keys the loader accepts there. The top level is the Session's
# fields plus format_version, as session_from_dict allows.
SECTIONS = {
    "Top level": loader_keys(Session) | {"format_version"},
    "`[venue]`": loader_keys(Venue),
    "`[[venue.beacons]]`": loader_keys(Beacon),
    "`[[venue.stands]]`": loader_keys(Stand),
    "`[[venue.map_points]]`": loader_keys(MapPoint),
    "`[[agents]]`": loader_keys(Agent),
    "`[[agents.sensors]]`": loader_keys(Sensor),
}


def documented() -> dict[str, dict[str, list[str]]]:
    """Section -> key -> the row's other cells (unit, default, accepted, meaning, when to change)."""
    sections: dict[str, dict[str, list[str]]] = {}
    current = None
    for line in DOC.read_text(encoding="utf-8").splitlines():
        heading = HEADING.match(line)
        if heading:
            current = next((name for name in SECTIONS if heading.group(1).startswith(name)), None)
            if current is not None:
                sections[current] = {}
            continue
        if current is None or not line.startswith("| `"):
            continue
        cells = [cell.strip() for cell in line.strip().strip("|").split(" | ")]
        for key in re.findall(r"`([a-z_]+)`", cells[0]):
            sections[current][key] = cells[1:]
    return sections


def test_every_loader_key_is_documented_and_every_documented_key_is_known():
    docs = documented()
    assert set(docs) == set(SECTIONS), "a section heading of docs/session-format.md changed"
    for section, keys in SECTIONS.items():
        assert set(docs[section]) == keys, (f"{section}: undocumented {sorted(keys - set(docs[section]))}, "
                                            f"documented but unknown {sorted(set(docs[section]) - keys)}")


def test_every_documented_key_has_unit_default_range_meaning_and_when_to_change_it():
    for section, rows in documented().items():
        for key, cells in rows.items():
            assert len(cells) == 5 and all(cells), f"{section} {key}: {cells}"


def test_a_dataclass_field_without_documentation_would_fail():
    """The comparison above is against the dataclasses, so a new field is caught."""
    extended = dataclasses.make_dataclass("Sensor", [("gain_db", float, 0.0)], bases=(Sensor,), frozen=True)
    assert loader_keys(extended) - set(documented()["`[[agents.sensors]]`"]) == {"gain_db"}


def good() -> dict:
    return {
        "venue": {"name": "court", "beacons": [{"id": "goal-a", "x_m": 1.575, "y_m": 7.5},
                                               {"id": "goal-b", "x_m": 26.425, "y_m": 7.5}],
                  "stands": [{"id": "door", "x_m": 1.0, "y_m": 1.0}]},
        "agents": [{"id": f"chair{i}", "sensors": [
            {"id": f"c{i}-seat", "mount": "seat"},
            {"id": f"c{i}-left", "mount": "left_wheel", "spin_axis": "+z"},
            {"id": f"c{i}-right", "mount": "right_wheel", "spin_axis": "-z"}]} for i in range(3)],
    }


def test_the_good_file_loads():
    session = session_from_dict(good(), where="venue.toml")
    assert len(session.agents) == 3 and session.agents[2].sensors[0].rate_hz == 200.0


def set_in(path: str, value):
    """A change to good(): `path` like agents.2.sensors.0.rate_hz; value DELETE removes the key."""
    def change(data):
        *parents, last = path.split(".")
        node = data
        for part in parents:
            node = node[int(part)] if part.isdigit() else node[part]
        if value is DELETE:
            del node[last]
        else:
            node[int(last) if last.isdigit() else last] = value
    return change


DELETE = object()
REFUSED = [
    ("agents.2.sensors.0.rate_hz", 0, r"venue.toml: agents\[2\].sensors\[0\].rate_hz: 0 is outside \[1.0, 10000.0\]"),
    ("agents.2.sensors.0.rate_hz", float("nan"), r"agents\[2\].sensors\[0\].rate_hz: nan is not a finite number"),
    ("agents.0.sensors.1.rate_hz", -200, r"agents\[0\].sensors\[1\].rate_hz: -200 is outside"),
    ("agents.0.sensors.0.rate_hz", "200", r"agents\[0\].sensors\[0\].rate_hz: '200' is not a finite number"),
    ("agents.0.sensors.0.rate_hz", True, r"rate_hz: True is not a finite number"),
    ("agents.0.sensors.0.rate", 200, r"agents\[0\].sensors\[0\].rate: unknown key \(allowed: .*rate_hz"),
    ("agents.0.sensors.0.mount", DELETE, r"agents\[0\].sensors\[0\]: missing key 'mount'"),
    ("agents.0.sensors.1.spin_axis", "z", r"agents\[0\].sensors\[1\].spin_axis: 'z' is not one of"),
    ("agents.1.wheel_diameter_m", -0.6, r"agents\[1\].wheel_diameter_m: -0.6 is outside \[0.2, 1.0\]"),
    ("agents.1.sensors", "seat", r"agents\[1\].sensors: expected a list of tables"),
    ("agents.1.id", "chair0", r"duplicate agent id 'chair0'"),
    ("agents.1.sensors.0.id", "c0-seat", r"duplicate sensor id 'c0-seat'"),
    ("venue.court_length_m", -28, r"venue.court_length_m: -28 is outside \[1.0, 500.0\]"),
    ("venue.court_width_m", float("inf"), r"venue.court_width_m: inf is not a finite number"),
    ("venue.beacons.0.radius_m", -1, r"venue.beacons\[0\].radius_m: -1 is outside \[0.1, 50.0\]"),
    ("venue.beacons.1.id", "goal-a", r"duplicate beacon id 'goal-a'"),
    ("venue.beacons.1.x_m", 280.0, (r"venue.beacons\[1\]: \(280, 7.5\) m is 252.00 m outside the 28 x 15 m court, "
                                    r"beyond its radius_m 1")),
    ("venue.beacons.0.y_m", -1.5, r"venue.beacons\[0\]: \(1.575, -1.5\) m is 1.50 m outside"),
    ("venue.beacons.0.identity", "ibeacon:nope", r"venue.beacons\[0\].identity: 'ibeacon:nope' is not"),
    ("venue.stands.0.floor", 1.5, r"venue.stands\[0\].floor: 1.5 is not a whole number"),
    ("venue.stands.0.colour", "red", r"venue.stands\[0\].colour: unknown key"),
    ("format_version", 2, r"venue.toml.format_version: 2 is not a format this reckon reads \(1 to 1"),
    ("format_version", "1", r"format_version: '1' is not a format"),
]


@pytest.mark.parametrize("path, value, message", REFUSED, ids=[f"{p}={v!r}" for p, v, _ in REFUSED])
def test_wrong_values_are_refused_naming_the_key(path, value, message):
    data = copy.deepcopy(good())
    set_in(path, value)(data)
    with pytest.raises(ConfigError, match=message):
        session_from_dict(data, where="venue.toml")


def test_a_beacon_just_off_the_court_within_its_radius_loads():
    data = copy.deepcopy(good())
    data["venue"]["beacons"][0].update(x_m=-0.9, radius_m=1.0)  # behind the end line, its zone reaches in
    assert session_from_dict(data).venue.beacons[0].x_m == -0.9


def test_a_toml_file_names_itself_and_the_key(tmp_path):
    path = write_venue(tmp_path / "venue.toml", "court", agents=[
        agent_table("walker", "pedestrian", sensors=[sensor_table("phone", "hand", rate_hz=math.nan)])])
    with pytest.raises(ConfigError, match=re.escape(f"{path}: agents[0].sensors[0].rate_hz: nan is not a finite")):
        load_toml(path)


SIMULATORS = ["sim_devices.wheelchair", "sim_devices.swim", "sim_devices.room", "sim_devices.pedestrian.params",
              "sim_devices.camera.params"]


@pytest.mark.parametrize("module", SIMULATORS)
def test_every_set_override_refuses_an_unknown_key_by_name(module):
    overrides = importlib.import_module(module).params_with_overrides
    with pytest.raises(ConfigError, match="--set nonsense_group.x: unknown group 'nonsense_group'"):
        overrides({"nonsense_group.x": "1"})


def test_device_urls_and_hub_corrections_refuse_unknown_names():
    from edge.sources.ble import parse_ble_url
    from edge.sources.serial import parse_serial_url
    from hub.chair.hub import HubSettings
    from edge.sources.phone.server import parse_phone_url

    with pytest.raises(ConfigError, match="unknown key 'bauds'"):
        parse_serial_url("serial:///dev/ttyUSB0?bauds=9600")
    with pytest.raises(ConfigError, match="unknown key 'tls'"):
        parse_phone_url("phone://0.0.0.0:8443?tls=x")
    with pytest.raises(ConfigError, match="'scan2' is not a Bluetooth address"):
        parse_ble_url("ble://scan2")
    with pytest.raises(ValueError, match=r"corrections \['beacons'\]: not among"):
        HubSettings(corrections=frozenset({"beacons"}))

"""Room worlds (sim_devices/room/worlds.py): world 0 is today's room, every other world draws the tracker's
errors and the people from their documented ranges, independently of the seed; `reckon sim room --world`
records it and `reckon eval --room-worlds` reports the spread over worlds."""

from __future__ import annotations

import json

import numpy as np
import pytest

from protocol.errors import ConfigError
from protocol.session_log import read_session
from reckon.cli import main
from sim_devices.camera import ROOM
from sim_devices.room import RoomParams
from sim_devices.room.worlds import ROOM_WORLD_RANGES, TRACKER, describe_room_worlds, draw_room_world, room_world


def _value(params: RoomParams, tracker, key: str) -> float:
    target, key = (tracker, key[len(TRACKER):]) if key.startswith(TRACKER) else (params, key)
    group, _, name = key.partition(".")
    return getattr(getattr(target, group), name)


def test_world_zero_is_todays_room_and_a_world_is_fixed_by_its_number():
    assert room_world(0) == (RoomParams(), ROOM) and draw_room_world(0) == {}
    assert room_world(5) == room_world(5) and room_world(5) != room_world(6)
    with pytest.raises(ConfigError, match="room world: -1"):
        room_world(-1)


def test_every_row_draws_inside_its_range_and_covers_it():
    draws = {row.key: [] for row in ROOM_WORLD_RANGES}
    for world in range(1, 201):
        params, tracker = room_world(world)
        for row in ROOM_WORLD_RANGES:
            value = _value(params, tracker, row.key)
            assert row.low <= value <= row.high, (world, row.key, value)
            draws[row.key].append(value)
    for row in ROOM_WORLD_RANGES:
        values = np.array(draws[row.key])
        span = row.high - row.low
        assert values.min() < row.low + 0.2 * span and values.max() > row.high - 0.2 * span, row.key
    assert [r[0] for r in describe_room_worlds()] == [row.name for row in ROOM_WORLD_RANGES]


def test_a_room_worlds_log_records_the_world_and_its_tracker(tmp_path):
    path = tmp_path / "room.mcap"
    assert main(["sim", "room", "--world", "4", "--duration", "15", "-o", str(path)]) == 0
    source = read_session(path).session.source
    params, tracker = room_world(4)
    assert source["world"] == 4
    assert source["tracker"]["params"]["gaps"]["rate_per_min"] == pytest.approx(tracker.gaps.rate_per_min)
    assert source["params"]["activity"]["sit_weight"] == pytest.approx(params.activity.sit_weight)


def test_eval_over_room_worlds_reports_the_spread_and_each_world(capsys):
    assert main(["eval", "--room-worlds", "1-2", "--duration", "30", "--jobs", "1", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [w["world"] for w in report["worlds"]] == [1, 2]
    methods = {(m["method"], m["track"]): m for m in report["methods"]}
    assert set(methods) == {("reckon", "live"), ("reckon", "refined"), ("hindsight", None), ("ceiling", None),
                            ("paper", None)}
    live = [w["time_correct_pct"]["reckon live"] for w in report["worlds"]]
    assert methods[("reckon", "live")]["median_pct"] == pytest.approx(np.median(live), abs=0.01)
    assert methods[("reckon", "live")]["worst_pct"] == pytest.approx(min(live), abs=0.01)
    assert report["worlds"][0]["figures"] == pytest.approx(draw_room_world(1))
    assert report["ours_live_above_paper"]["worlds"] == 2

"""The hub's map of the hall's magnetic field (hub/chair/field_map.py): learnt from every chair's
readings, each chair given the map without its own, and sent only while it predicts readings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hub.chair.field_map import FieldMap, FieldMapSettings
from protocol import messages
from protocol.session import Venue

DEG = math.pi / 180.0
VENUE = Venue(name="court")
CHAIRS = [f"chair{k}" for k in range(1, 7)]


def hall(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A disturbance smooth over metres, 8 deg RMS."""
    return 16.0 * DEG * np.sin(2.0 * math.pi * x / 14.0 + 0.5) * np.cos(2.0 * math.pi * y / 11.0 + 0.3)


def reading(agent: str, x: float, y: float, offset: float, variance: float = (2.0 * DEG) ** 2) -> object:
    return messages.new("FieldReading", timestamp_ns=0, agent_id=agent, x_m=x, y_m=y, offset_rad=offset,
                        variance_rad2=variance)


def feed(field: FieldMap, rng: np.random.Generator, readings: int, disturbance=hall,
         chair_offsets: dict[str, float] | None = None) -> None:
    """Each chair at random places, its own heading error (constant 2 deg + 1 deg that changes) added."""
    offsets = chair_offsets or {agent: rng.normal(0.0, 2.0 * DEG) for agent in CHAIRS}
    for _ in range(readings):
        for agent in CHAIRS:
            x, y = rng.uniform(0.0, 28.0), rng.uniform(0.0, 15.0)
            field.add(reading(agent, x, y, float(disturbance(np.array([x]), np.array([y]))[0]) + offsets[agent]
                              + rng.normal(0.0, 1.0 * DEG)))


def lookup(message, x: float, y: float) -> tuple[float, float]:
    column = math.floor((x - message.origin_x_m) / message.cell_m)
    row = math.floor((y - message.origin_y_m) / message.cell_m)
    k = row * message.columns + column
    return message.offset_rad[k], message.variance_rad2[k]


def test_the_map_learns_a_smooth_hall_from_six_chairs():
    rng = np.random.default_rng(1)
    field = FieldMap(VENUE, CHAIRS)
    feed(field, rng, 300)
    assert field.trusted
    maps = field.maps(10**10)
    assert [m.agent_id for m in maps] == CHAIRS
    m = maps[0]
    errors, truth = [], []
    for x in np.arange(1.0, 27.0, 2.0):
        for y in np.arange(1.0, 14.0, 2.0):
            offset, variance = lookup(m, x, y)
            assert variance > 0.0
            errors.append(offset - float(hall(np.array([x]), np.array([y]))[0]))
            truth.append(float(hall(np.array([x]), np.array([y]))[0]))
    errors = np.array(errors) - np.mean(errors)  # a common offset is each chair's north to absorb
    assert np.sqrt(np.mean(errors**2)) < 0.4 * np.sqrt(np.mean(np.array(truth) ** 2))
    # the variance the edges are told covers what the map gets wrong at the cell centres
    variance = np.mean([lookup(m, x, 7.0)[1] for x in np.arange(1.0, 27.0, 2.0)])
    assert variance >= 0.5 * np.mean(errors**2)
    assert "sent" in field.describe()


def test_a_chair_is_not_told_its_own_readings():
    field = FieldMap(VENUE, CHAIRS, FieldMapSettings(min_chairs=2, check_min=0, explained_share=2.0))
    for _ in range(20):  # only chair1 and chair2 read this cell, chair3 another
        field.add(reading("chair1", 5.0, 5.0, 10.0 * DEG))
        field.add(reading("chair2", 5.0, 5.0, 10.0 * DEG))
        field.add(reading("chair3", 20.0, 10.0, 0.0))
    field.add(reading("chair4", 20.0, 10.0, 0.0))
    field.checked = 1  # the predictive check needs a cell known without the reader: none here
    field.residual_sq, field.raw_sq = 0.0, 1.0
    by_agent = {m.agent_id: m for m in field.maps(10**10)}
    offset, variance = lookup(by_agent["chair3"], 5.0, 5.0)
    assert offset == pytest.approx(10.0 * DEG) and variance > 0.0
    assert lookup(by_agent["chair1"], 5.0, 5.0)[1] == 0.0  # one other chair only: not known for chair1
    assert lookup(by_agent["chair3"], 20.0, 10.0)[1] == 0.0


def test_a_hall_without_structure_gets_no_map_and_a_map_that_stops_predicting_is_withdrawn():
    rng = np.random.default_rng(2)
    field = FieldMap(VENUE, CHAIRS)
    feed(field, rng, 300)
    assert field.trusted and field.maps(10**10)
    # the field now changes from reading to reading (a lost hard-iron fit, steel that moves): no map
    feed(field, rng, 400, disturbance=lambda x, y: rng.normal(0.0, 10.0 * DEG, len(x)))
    assert not field.trusted
    withdrawn = field.maps(2 * 10**10)
    assert withdrawn and all(m.columns == 0 and not m.offset_rad for m in withdrawn)
    assert field.maps(3 * 10**10) == []  # said once
    noisy = FieldMap(VENUE, CHAIRS)
    feed(noisy, np.random.default_rng(3), 300, disturbance=lambda x, y: rng.normal(0.0, 10.0 * DEG, len(x)))
    assert not noisy.trusted and noisy.maps(10**10) == []
    assert "not sent" in noisy.describe()


def test_each_chairs_constant_offset_is_learnt_and_lost_headings_refused():
    rng = np.random.default_rng(4)
    field = FieldMap(VENUE, CHAIRS)
    offsets = {agent: 0.0 for agent in CHAIRS}
    offsets["chair2"] = 6.0 * DEG  # learnt its north where the hall bends 6 deg
    feed(field, rng, 300, chair_offsets=offsets)
    learnt = field.chair_offset - np.mean(field.chair_offset)
    assert abs(learnt[1] - (6.0 * DEG - 6.0 * DEG / len(CHAIRS))) < 2.0 * DEG
    assert np.all(np.abs(np.delete(learnt, 1)) < 2.5 * DEG)
    before = field.count.sum()
    field.add(reading("chair1", 5.0, 5.0, 90.0 * DEG))  # a heading lost by far
    field.add(reading("chair1", 500.0, 5.0, 0.0))  # off the map
    field.add(reading("stranger", 5.0, 5.0, 0.0))
    field.add(reading("chair1", 5.0, 5.0, math.nan))
    assert field.refused == 4 and field.count.sum() == before


def test_maps_go_out_every_period_to_the_chairs_that_read():
    field = FieldMap(VENUE, CHAIRS, FieldMapSettings(period_s=5.0))
    assert not field.due(0)  # nobody reads yet, and the first period starts now
    feed(field, np.random.default_rng(5), 300)
    assert not field.due(4 * 10**9) and field.due(5 * 10**9)
    assert len(field.maps(5 * 10**9)) == len(CHAIRS)
    assert not field.due(9 * 10**9) and field.due(10 * 10**9)


@pytest.mark.parametrize("bad", [dict(cell_m=0.0), dict(period_s=math.nan), dict(chair_memory=0.5), dict(min_chairs=0),
                                 dict(margin_m=-1.0)])
def test_a_wrong_setting_is_refused_by_name(bad):
    (name, value), = bad.items()
    with pytest.raises(ValueError, match=f"{name} = {value}"):
        FieldMapSettings(**bad)

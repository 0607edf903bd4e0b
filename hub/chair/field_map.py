"""The hall's magnetic field as every chair saw it: a map the hub learns and hands back to each edge.

A building's disturbance is fixed in space and the same for every chair, and it turns each seat
magnetometer's north by the same few degrees in the same places, smoothly over metres. One chair
cannot tell such a bend from a turn of its own (its aid follows the field, docs/reckon-estimator.md);
ten chairs passing the same spot with independent heading errors can. Each edge offers its
readings (`FieldReading`: where it was, the field's angle less its own north - heading, and that
difference's variance); per grid cell and chair the hub keeps a running mean, and a cell's offset is
the precision-weighted mean over chairs, each chair's own constant offset (the disturbance where
it learned north) taken out.

Every edge gets the map without its own readings (leave one out): a chair must not be told its
own heading error back as the hall's. The map checks itself before anyone uses it: each reading
is first predicted from the other chairs' map, and only while that prediction beats no map at
all (mean squared residual below `explained_share` of the readings' own) is a map sent; what the
prediction leaves, squared, is the variance the edge is told (it also holds the reading chair's
heading error, so it over-states the map's: an edge trusts a map less than it could, never more).
Where the map is not trusted an empty one goes out, and the edges fall back to their own model of
the hall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocol import messages
from protocol.session import Venue

DEG = math.pi / 180.0


@dataclass(frozen=True)
class FieldMapSettings:
    cell_m: float = 2.0  # a disturbance correlated over 1-10 m (issue 21's range) is resolved from ~2 m on
    margin_m: float = 2.0  # the map reaches this far beyond the court's lines (benches, run-outs)
    min_chairs: int = 2  # a cell is known once this many other chairs have read it
    reading_sd_deg: float = 3.0  # one reading's own scatter within a cell (noise, the field across the cell)
    max_offset_deg: float = 45.0  # a reading this far from the edge's own north - heading is a lost heading
    chair_memory: float = 20.0  # readings: forgetting of one chair's mean in one cell
    check_memory: float = 200.0  # readings: forgetting of the map's predictive check
    check_min: int = 50  # predictions before the map may be sent
    explained_share: float = 0.7  # sent while its predictions' mean squared residual is below this share of no map's
    period_s: float = 5.0  # a new map this often (venue time)

    def __post_init__(self) -> None:
        positive = ("cell_m", "reading_sd_deg", "max_offset_deg", "explained_share", "period_s")
        for name in positive:
            if not 0.0 < getattr(self, name) < math.inf:  # refuses NaN too
                raise ValueError(f"field map setting {name} = {getattr(self, name)}: must be finite and > 0")
        for name in ("chair_memory", "check_memory"):
            if not 1.0 <= getattr(self, name) < math.inf:
                raise ValueError(f"field map setting {name} = {getattr(self, name)}: must be finite and >= 1 (readings)")
        if not (0.0 <= self.margin_m < math.inf and self.min_chairs >= 1 and self.check_min >= 0):
            raise ValueError(f"field map settings margin_m = {self.margin_m} (finite, >= 0), min_chairs = "
                             f"{self.min_chairs} (>= 1), check_min = {self.check_min} (>= 0)")


class FieldMap:
    """`add(reading)`, then `maps(time_ns)` (a FieldMap message per reading agent) when `due(time_ns)`."""

    def __init__(self, venue: Venue, agent_ids: list[str], settings: FieldMapSettings = FieldMapSettings()):
        self.settings = settings
        self.origin = (-settings.margin_m, -settings.margin_m)
        self.columns = math.ceil((venue.court_length_m + 2 * settings.margin_m) / settings.cell_m)
        self.rows = math.ceil((venue.court_width_m + 2 * settings.margin_m) / settings.cell_m)
        self.index = {agent: k for k, agent in enumerate(agent_ids)}
        shape = (len(agent_ids), self.rows * self.columns)
        self.count = np.zeros(shape)  # per chair and cell, with forgetting: readings,
        self.total = np.zeros(shape)  # their offsets' sum,
        self.variance = np.zeros(shape)  # and their heading variances' sum
        self.chair_offset = np.zeros(len(agent_ids))  # each chair's constant: north learned where the hall bends
        self.readers: dict[str, None] = {}  # agents that sent readings, in order: they get maps
        self.checked = 0
        self.residual_sq = 0.0  # the predictive check's running means: with the other chairs' map,
        self.raw_sq = 0.0  # and with none
        self.refused = 0  # readings beyond max_offset_deg or off the map
        self.next_ns: int | None = None
        self.sent_trusted = False

    # -- readings ------------------------------------------------------------------------------

    def add(self, reading: Any) -> None:
        agent = self.index.get(reading.agent_id)
        cell = self.cell_of(reading.x_m, reading.y_m)
        offset = reading.offset_rad
        if (agent is None or cell is None or not math.isfinite(offset) or not reading.variance_rad2 >= 0.0
                or abs(offset) > self.settings.max_offset_deg * DEG):
            self.refused += 1
            return
        self.readers.setdefault(reading.agent_id, None)
        own = offset - self.chair_offset[agent]
        predicted = self._cell_without(agent, cell)
        if predicted is not None:
            residual = own - predicted[0]
            keep = 1.0 - 1.0 / self.settings.check_memory
            self.residual_sq = keep * self.residual_sq + (1.0 - keep) * residual * residual
            self.raw_sq = keep * self.raw_sq + (1.0 - keep) * own * own
            self.checked += 1
            # the chair's constant: what the others' map leaves of its readings, on average
            self.chair_offset[agent] += residual / self.settings.chair_memory
        keep = 1.0 - 1.0 / self.settings.chair_memory
        self.count[agent, cell] = keep * self.count[agent, cell] + 1.0
        self.total[agent, cell] = keep * self.total[agent, cell] + offset
        self.variance[agent, cell] = keep * self.variance[agent, cell] + reading.variance_rad2

    def cell_of(self, x_m: float, y_m: float) -> int | None:
        column = math.floor((x_m - self.origin[0]) / self.settings.cell_m)
        row = math.floor((y_m - self.origin[1]) / self.settings.cell_m)
        if not (0 <= column < self.columns and 0 <= row < self.rows):
            return None
        return row * self.columns + column

    @property
    def trusted(self) -> bool:
        """The map predicts the readings better than no map, by the margin the settings ask."""
        s = self.settings
        return self.checked >= s.check_min and self.residual_sq <= s.explained_share * self.raw_sq

    # -- the map -------------------------------------------------------------------------------

    def _weights(self, cells: slice | int = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(weight, weight x mean) per chair of `cells` (all: chairs x cells): each chair's mean with its
        own offset out, weighted by its precision (its heading's variance, the readings' scatter over
        their number); 0 where a chair has not read the cell."""
        count, total, variance = self.count[:, cells], self.total[:, cells], self.variance[:, cells]
        seen = count > 0.0
        count = np.where(seen, count, 1.0)
        offset = self.chair_offset if isinstance(cells, int) else self.chair_offset[:, None]
        mean = total / count - offset
        weight = np.where(seen, 1.0 / (variance / count + (self.settings.reading_sd_deg * DEG) ** 2 / count), 0.0)
        return weight, weight * mean

    def _cell_without(self, agent: int, cell: int) -> tuple[float, float] | None:
        """(offset, variance) of one cell from every chair but `agent`; None: too few chairs there."""
        seen = self.count[:, cell] > 0.0
        seen[agent] = False
        if int(seen.sum()) < self.settings.min_chairs:
            return None
        weight, weighted = self._weights(cell)
        total = float(weight[seen].sum())
        return float(weighted[seen].sum()) / total, 1.0 / total

    def due(self, time_ns: int) -> bool:
        if self.next_ns is None:
            self.next_ns = time_ns + int(self.settings.period_s * 1e9)
        return time_ns >= self.next_ns and bool(self.readers)

    def maps(self, time_ns: int) -> list[Any]:
        """A FieldMap for each agent that sends readings, each without its own; empty ones (no cells)
        when the map stopped predicting the readings (once, then nothing until it does again)."""
        self.next_ns = time_ns + int(self.settings.period_s * 1e9)
        if not self.trusted:
            if not self.sent_trusted:
                return []
            self.sent_trusted = False
            return [self._message(agent, time_ns, None, None) for agent in self.readers]
        self.sent_trusted = True
        weight, weighted = self._weights()
        seen = self.count > 0.0
        all_weight, all_weighted, chairs = weight.sum(axis=0), weighted.sum(axis=0), seen.sum(axis=0)
        out = []
        for agent_id in self.readers:
            k = self.index[agent_id]
            others = all_weight - weight[k]
            known = (chairs - seen[k]) >= self.settings.min_chairs
            safe = np.where(known, others, 1.0)
            offset = np.where(known, (all_weighted - weighted[k]) / safe, 0.0)
            variance = np.where(known, np.maximum(1.0 / safe, self.residual_sq), 0.0)
            out.append(self._message(agent_id, time_ns, offset, variance))
        return out

    def _message(self, agent_id: str, time_ns: int, offset: np.ndarray | None, variance: np.ndarray | None) -> Any:
        empty = offset is None
        return messages.new("FieldMap", timestamp_ns=int(time_ns), agent_id=agent_id, origin_x_m=self.origin[0],
                            origin_y_m=self.origin[1], cell_m=self.settings.cell_m,
                            columns=0 if empty else self.columns, rows=0 if empty else self.rows,
                            offset_rad=[] if empty else offset.tolist(),
                            variance_rad2=[] if empty else variance.tolist())

    def describe(self) -> str:
        """One line for the hub's closing summary."""
        if not self.checked:
            return f"field map: {len(self.readers)} chairs reading, no cell read by enough chairs yet"
        return (f"field map: {len(self.readers)} chairs, {self.checked} readings predicted, residual "
                f"{math.sqrt(self.residual_sq) / DEG:.1f} deg against {math.sqrt(self.raw_sq) / DEG:.1f} without the "
                f"map ({'sent' if self.trusted else 'not sent'}), {self.refused} refused")

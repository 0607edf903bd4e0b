"""Collisions: impacts seen by two chairs at once, paired into contacts (the chairs' hub uses it).

Impacts within `window_s` of the first form a group, closed once every live agent's poses have
passed it by `lateness_s` (an agent silent for `stale_s`, hub clock, no longer holds it back). Every
pair in the group is scored by how well the two estimates fit a contact (chi-square with both
covariances) and how close in time its two impacts came (chi-square against the spread the contacts
taken so far show, `ContactTiming`: a pile-up of two contacts 0.1 s apart is two pairs, not a
cross-pairing of its four impacts); a pair whose two pushes (each impact's horizontal force, turned
by its chair's heading) do not point opposite ways is no contact; pairs inside the gates are taken
best first, each chair at most once, so three or more impacts at once still yield their pairs. A pair becomes one
relative constraint: each chair gets the measurement of the other's side (exactly the joint update
of two independent estimates). The pushes also say which way the other chair was (action and
reaction point along the line between the centres), so the constraint holds across the line too,
within `PUSH_LINE_SD` of its direction; without pushes it holds along the estimates' line only.
Each side's measurement is weighted down (Huber) when it lies more than `CONTACT_HUBER_SDS` from its
chair's pose: a true contact with a chair whose dead reckoning is metres off while stating less would
otherwise drag the chair it touched as far (world 36: all 28 pairs true, collisions 14 % worse).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from typing import Any, NamedTuple

import numpy as np

from hub.chair.corrections import CONTACT_GATE_CHI2, FIX_GATE_CHI2, ContactDistance, ContactTiming, mahalanobis2
from hub.chair.view import AgentView

ACROSS_VARIANCE_M2 = 1e4  # a contact says nothing about the direction across the line between chairs
PUSH_GATE_COS = math.cos(math.radians(60.0))  # both headings' errors, and pushes off the line between centres
PUSH_LINE_SD = math.radians(20.0)  # spread of the pushes' line about the centres' (both headings, glancing contacts)
WINDOW_SDS = 3.29  # the pairing window spans this many of the timing prior's sd either way (99.9 %)
IMPACTS_HELD = 256  # open impacts, venue-wide; beyond that the oldest goes unpaired
# Beyond this many SDs (the measurement against its chair's pose) a side's covariance grows with its size:
# its pull is then bounded. Chosen from 1 / 1.5 / 2 / 3 on worlds 1-10 and 31-50 (docs/reckon-estimator.md,
# "More worlds, and stray beacon candidates").
CONTACT_HUBER_SDS = 1.5


class ContactFix(NamedTuple):
    """One side of a contact: where `agent` was at `time_ns` relative to its pose then, as the other saw it."""

    agent: str
    other: str
    time_ns: int
    measured: np.ndarray  # the shift (m, court frame)
    covariance: np.ndarray  # 2 x 2


class ImpactPairing:
    """The open impacts and the contact distance learnt from the pairs taken. `counters` (the hub's)
    counts impacts, late impacts, groups, pairs, gated-out and not-opposed pairs."""

    def __init__(self, window_s: float, lateness_s: float, stale_s: float, counters: Any):
        self.counters = counters
        self.contact = ContactDistance()
        self.timing = ContactTiming(prior_sd_s=window_s / WINDOW_SDS)
        self.impacts: deque[tuple[int, str, float, float]] = deque(maxlen=IMPACTS_HELD)  # (time, agent, push)
        self.closed_until_ns = -1
        self._window_ns = int(window_s * 1e9)  # a group's span
        self._hold_ns = self._window_ns + lateness_s * 1e9  # ... and how long it waits after its first
        self._stale_ns = stale_s * 1e9
        # The pairing waits until every live agent's poses pass the oldest open impact (+ the hold).
        # The agents still short of it are found once per oldest impact and leave as they pass, so
        # a pose costs O(1) instead of a scan of every agent (500 chairs: 25,000 scans a second).
        self._oldest_ns: int | None = None  # None: to be found again (the set below with it)
        # A dict used as an ordered set: a set's iteration order depends on its add/discard history,
        # so a snapshot restored and caught up (reckon/processes/checkpoint.py) would pickle differently.
        self._short: dict[str, None] = {}

    def add(self, time_ns: int, agent_id: str, forward_g: float, left_g: float) -> None:
        """An impact above the threshold, in venue time, with its push (chair frame; both 0: unknown)."""
        self.counters.impacts += 1
        if time_ns <= self.closed_until_ns:
            self.counters.late_impacts += 1
        if self._oldest_ns is not None and (time_ns < self._oldest_ns or len(self.impacts) == self.impacts.maxlen):
            self._oldest_ns = None  # an older impact, or the oldest falls out of the deque
        self.impacts.append((time_ns, agent_id, forward_g, left_g))

    def agents_changed(self) -> None:
        """An agent's timeline restarted: who is short of the oldest impact is to be found again."""
        self._oldest_ns = None

    def close(self, posed: AgentView, agents: dict[str, AgentView], newest_arrival_ns: int) -> list[ContactFix]:
        """The contacts of the groups every live agent's poses have passed (called with every pose;
        `posed` has just moved on)."""
        if not self.impacts or self._live_agent_short(posed, agents, newest_arrival_ns):
            return []  # the usual case: nothing to close yet
        watermark = self._watermark(agents, newest_arrival_ns)
        window_ns, hold_ns = self._window_ns, self._hold_ns
        if watermark is None or min(self.impacts)[0] + hold_ns > watermark:
            return []
        ordered = sorted(self.impacts)
        out: list[ContactFix] = []
        while ordered and ordered[0][0] + hold_ns <= watermark:
            first_ns = ordered[0][0]
            group = [item for item in ordered if item[0] - first_ns <= window_ns]
            ordered = ordered[len(group):]
            self.closed_until_ns = max(self.closed_until_ns, group[-1][0])
            firsts: dict[str, tuple[int, float, float]] = {}
            for impact_ns, agent, forward_g, left_g in group:
                firsts.setdefault(agent, (impact_ns, forward_g, left_g))  # an agent's first impact in the group
            if len(firsts) >= 2:
                self.counters.groups += 1
                out += self._pair(first_ns, sorted(firsts), firsts, agents)
        self.impacts = deque(ordered, maxlen=self.impacts.maxlen)
        self._oldest_ns = None
        return out

    def _watermark(self, agents: dict[str, AgentView], newest_arrival_ns: int) -> int | None:
        """Venue time every live agent's poses have reached."""
        latest = [v.latest_ns for v in agents.values()
                  if v.latest_ns is not None and newest_arrival_ns - v.arrival_ns <= self._stale_ns]
        return min(latest) if latest else None

    def _live_agent_short(self, posed: AgentView, agents: dict[str, AgentView], newest_arrival_ns: int) -> bool:
        """Whether a live agent's poses are still short of the oldest impact + the hold (then no group
        can close: the watermark is below it)."""
        hold_ns = self._hold_ns
        if self._oldest_ns is None:
            self._oldest_ns = min(self.impacts)[0]
            due = self._oldest_ns + hold_ns
            self._short = {v.agent_id: None for v in agents.values() if v.latest_ns is not None and v.latest_ns < due}
        due = self._oldest_ns + hold_ns
        if posed.latest_ns < due:
            self._short[posed.agent_id] = None  # also an agent whose first pose this is
        else:
            self._short.pop(posed.agent_id, None)
        stale_ns = self._stale_ns
        for agent_id in self._short:  # usually the first is live
            if newest_arrival_ns - agents[agent_id].arrival_ns <= stale_ns:
                return True
        return False

    def _pair(self, time_ns: int, names: list[str], firsts: dict[str, tuple[int, float, float]],
              agents: dict[str, AgentView]) -> list[ContactFix]:
        candidates = []
        contact_m, contact_var = self.contact.mean_m(), self.contact.variance_m2()
        timing_var = self.timing.variance_s2()
        for a, b in itertools.combinations(names, 2):
            apart_s = (firsts[a][0] - firsts[b][0]) * 1e-9
            timing_score = apart_s * apart_s / timing_var
            if timing_score > CONTACT_GATE_CHI2:
                self.counters.not_simultaneous += 1
                continue
            pose_a, pose_b = agents[a].pose_at(time_ns), agents[b].pose_at(time_ns)
            if pose_a is None or pose_b is None:
                continue
            delta = pose_a[0] - pose_b[0]
            distance = float(np.hypot(*delta))
            if distance < 1e-6:
                continue
            unit = delta / distance
            var_a, var_b = float(unit @ pose_a[1] @ unit), float(unit @ pose_b[1] @ unit)
            innovation = contact_m - distance
            score = innovation * innovation / (var_a + var_b + contact_var)
            if score > CONTACT_GATE_CHI2:
                self.counters.gated_out += 1
                continue
            opposed, line = _push_line(agents[a].heading_at(time_ns), agents[b].heading_at(time_ns),
                                       firsts[a][1:], firsts[b][1:])
            if not opposed:
                self.counters.pushes_not_opposed += 1
            elif line is not None and mahalanobis2(contact_m * line - delta, pose_a[1] + pose_b[1]
                                                   + _push_shape(line, contact_m, contact_var)) > FIX_GATE_CHI2:
                self.counters.gated_out += 1  # where the pushes put the other chair, the poses do not
            else:
                candidates.append((score + timing_score, a, b, unit, innovation, var_a, var_b, line, delta,
                                   pose_a[1], pose_b[1], apart_s))
        out: list[ContactFix] = []
        taken: set[str] = set()
        for _, a, b, unit, innovation, var_a, var_b, line, delta, cov_a, cov_b, apart_s in sorted(candidates,
                                                                                                 key=lambda c: c[0]):
            if a in taken or b in taken:
                continue
            taken |= {a, b}
            self.counters.pairs += 1
            self.contact.taken(contact_m - innovation, var_a + var_b)
            self.timing.taken(apart_s)
            if line is not None:  # the pushes say where the other chair was, along the line and across it
                shape = _push_shape(line, contact_m, contact_var)
                offset = contact_m * line - delta
                out += [_robust(ContactFix(a, b, time_ns, offset, cov_b + shape), cov_a),
                        _robust(ContactFix(b, a, time_ns, -offset, cov_a + shape), cov_b)]
                continue
            across = np.array([-unit[1], unit[0]])
            for me, other, direction, noise, own in ((a, b, unit, var_b, cov_a), (b, a, -unit, var_a, cov_b)):
                covariance = (noise + contact_var) * np.outer(direction, direction) + ACROSS_VARIANCE_M2 * np.outer(across, across)
                out.append(_robust(ContactFix(me, other, time_ns, direction * innovation, covariance), own))
        return out


def _robust(fix: ContactFix, own_covariance: np.ndarray) -> ContactFix:
    """`fix` with its covariance grown by its size beyond CONTACT_HUBER_SDS (Huber's weight), the size
    taken against the chair's own pose covariance and the fix's."""
    size = math.sqrt(mahalanobis2(fix.measured, own_covariance + fix.covariance))
    if size <= CONTACT_HUBER_SDS:
        return fix
    return fix._replace(covariance=fix.covariance * (size / CONTACT_HUBER_SDS))


def _push_line(heading_a: float | None, heading_b: float | None, push_a: tuple[float, float],
               push_b: tuple[float, float]) -> tuple[bool, np.ndarray | None]:
    """(opposed, line): whether the two impacts' pushes point within `PUSH_GATE_COS` of opposite
    ways, as one contact's action and reaction do (two bumps that merely coincide, a ball, a hard
    push, the floor, point any way), and the line from b to a they say (unit, court frame).
    Unknown pushes or headings: (True, None)."""
    unit_a = None if heading_a is None else _court_unit(push_a, heading_a)
    unit_b = None if heading_b is None else _court_unit(push_b, heading_b)
    if unit_a is None or unit_b is None:
        return True, None
    if -float(unit_a @ unit_b) < PUSH_GATE_COS:
        return False, None
    line = unit_a - unit_b
    return True, line / float(np.hypot(*line))


def _court_unit(push: tuple[float, float], heading: float) -> np.ndarray | None:
    """A push in the chair frame (forward, left) as a unit vector in the court frame; None if unknown."""
    forward, left = push
    size = math.hypot(forward, left)
    if size == 0.0:
        return None
    c, s = math.cos(heading), math.sin(heading)
    return np.array([c * forward - s * left, s * forward + c * left]) / size


def _push_shape(line: np.ndarray, contact_m: float, contact_var: float) -> np.ndarray:
    """Covariance of where a contact's pushes put the other chair: the contact distance's spread along
    their line, `PUSH_LINE_SD` of its direction across it."""
    across = np.array([-line[1], line[0]])
    return contact_var * np.outer(line, line) + (contact_m * PUSH_LINE_SD) ** 2 * np.outer(across, across)

"""What an import did: samples per sensor, rows skipped with their reasons, warnings."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

EXAMPLES_PER_FILE = 5  # skipped rows listed in full per file; the rest are only counted


@dataclass
class SensorCount:
    agent_id: str
    samples: int = 0
    batches: int = 0
    first_s: float = 0.0  # first and last sample time, seconds in the sensor's clock
    last_s: float = 0.0


@dataclass
class ImportReport:
    """Summary of one import. `str(report)` is the human summary the CLI prints."""

    output: Path
    sensors: dict[str, SensorCount] = field(default_factory=dict)
    sightings: int = 0
    truth_poses: int = 0
    skipped: Counter[str] = field(default_factory=Counter)  # "file: reason" -> rows
    skip_examples: list[str] = field(default_factory=list)  # "file line N: detail", first few per file
    warnings: list[str] = field(default_factory=list)
    _examples_per_file: Counter[str] = field(default_factory=Counter, init=False, repr=False)

    @property
    def rows_skipped(self) -> int:
        return sum(self.skipped.values())

    def skip(self, file: str, line: int, reason: str, detail: str) -> None:
        """Count one skipped row; keep its full description if it is among the file's first few."""
        self.skipped[f"{file}: {reason}"] += 1
        self._examples_per_file[file] += 1
        if self._examples_per_file[file] <= EXAMPLES_PER_FILE:
            self.skip_examples.append(f"{file} line {line}: {detail}")

    def warn(self, message: str) -> None:
        self.warnings.append(message)

    def __str__(self) -> str:
        lines = [f"imported {len(self.sensors)} sensors into {self.output}"]
        for sensor_id, count in self.sensors.items():
            span_s = count.last_s - count.first_s
            rate = f", {(count.samples - 1) / span_s:.1f} Hz" if count.samples > 1 and span_s > 0 else ""
            lines.append(f"  {count.agent_id}/{sensor_id}: {count.samples} samples in {count.batches} batches, "
                         f"{count.first_s:.3f}-{count.last_s:.3f} s{rate}")
        lines.append(f"  beacon sightings: {self.sightings}; truth poses: {self.truth_poses}")
        if self.skipped:
            lines.append(f"skipped {self.rows_skipped} rows:")
            lines.extend(f"  {count} x {what}" for what, count in sorted(self.skipped.items()))
            lines.append("  first skipped rows:")
            lines.extend(f"    {example}" for example in self.skip_examples)
        else:
            lines.append("skipped no rows")
        if self.warnings:
            lines.append("warnings:")
            lines.extend(f"  - {warning}" for warning in self.warnings)
        return "\n".join(lines)


OUTSIDE_SHOWN = 8  # truth positions outside the walkable area listed by name; the rest are counted


@dataclass(frozen=True)
class WalkableCheck:
    """Truth positions against the hub's walkable area (hub/pedestrian/walkable.py, as the hub
    builds it from the session's venue): how many lie inside, and each one outside with its
    distance to the area in metres, in order. A position outside is a map problem to report (a
    shop drawn over a corridor, a frame off), not an import error. `problem`: why nothing could
    be checked (the hub finds no walkable area in the plan)."""

    total: int
    outside: tuple[tuple[str, float], ...] = ()  # (label such as "wp 12", metres outside)
    problem: str = ""

    @property
    def inside(self) -> int:
        return self.total - len(self.outside)

    @staticmethod
    def combine(checks: list[tuple[str, "WalkableCheck"]]) -> "WalkableCheck":
        """Several walks' checks as one, each label prefixed with its walk's name."""
        problems = sorted({check.problem for _, check in checks if check.problem})
        return WalkableCheck(sum(check.total for _, check in checks),
                             tuple((f"{name} {label}", distance_m) for name, check in checks
                                   for label, distance_m in check.outside), "; ".join(problems))

    def __str__(self) -> str:
        return self.text("walkable")

    def text(self, name: str) -> str:
        """`name: 44 of 47 waypoints inside; outside: ...`, the farthest named."""
        if self.problem:
            return f"{name}: not checked ({self.problem})"
        text = f"{name}: {self.inside} of {self.total} waypoints inside"
        if not self.outside:
            return text
        shown = ", ".join(f"{label} {distance_m:.2f} m" for label, distance_m in self.outside[:OUTSIDE_SHOWN])
        more = f", and {len(self.outside) - OUTSIDE_SHOWN} more" if len(self.outside) > OUTSIDE_SHOWN else ""
        farthest, distance_m = max(self.outside, key=lambda item: item[1])
        return f"{text}; outside: {shown}{more}; farthest {farthest}, {distance_m:.2f} m"

"""Streaming reader for IMU tables in CSV: header -> column layout with units, rows -> numpy arrays.

Shared by the CSV-folder and NGIMU importers; each parses its own header names into
(quantity, axis, unit) and this module does the rest. Rules (docs/csv-import.md):

- a missing column, an unknown unit or a column given twice: InputError naming the file, the
  column and what was found;
- a row with the wrong number of fields, or a field that is not a finite number: skipped, counted
  in the ImportReport with file, line and value;
- a row whose time is not after the previous row's: InputError naming file, line and both values,
  except a repeated sample (every value equal to the previous row's, time equal or at most 1 ms
  earlier), which is skipped and counted: some loggers write a sample twice (the x-io NGIMU does,
  at the same time or 4 us earlier);
- times are parsed as exact decimals into integer nanoseconds (no float rounding at unix times).
"""

from __future__ import annotations

import csv
import math
from array import array
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from decimal import ROUND_HALF_EVEN, Decimal
from pathlib import Path

import numpy as np

from protocol.errors import InputError
from reckon.importers.report import ImportReport

STANDARD_GRAVITY_MPS2 = 9.80665  # CGPM 1901, the g of accelerometer data sheets
NS_PER_TIME_UNIT = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
# Multipliers from the unit written in a header to the unit the protocol stores.
TO_PROTOCOL_UNIT: dict[str, dict[str, float]] = {
    "accel": {"g": 1.0, "mg": 1e-3, "mps2": 1.0 / STANDARD_GRAVITY_MPS2, "m/s^2": 1.0 / STANDARD_GRAVITY_MPS2,
              "m/s2": 1.0 / STANDARD_GRAVITY_MPS2},
    "gyro": {"dps": 1.0, "degps": 1.0, "deg/s": 1.0, "radps": 180.0 / math.pi, "rad/s": 180.0 / math.pi},
    "mag": {"gauss": 1.0, "mgauss": 1e-3, "ut": 1e-2, "nt": 1e-5},  # 1 gauss = 100 uT = 1e5 nT
}
QUANTITIES = ("accel", "gyro", "mag")
AXES = ("x", "y", "z")
MAX_TIME_NS = 2**63 - 1  # int64 nanoseconds: year 2262 in unix time
REPEAT_WINDOW_NS = 1_000_000  # a repeated sample's time is at most 1 ms before the original's


@dataclass(frozen=True)
class HeaderName:
    """What one header cell means: quantity ("time", "accel", "gyro", "mag"), axis, unit as written."""

    quantity: str
    axis: str
    unit: str


@dataclass(frozen=True)
class Column:
    index: int
    name: str
    scale: float  # header unit -> protocol unit (time: nanoseconds per unit)


@dataclass(frozen=True)
class ImuLayout:
    time: Column
    axes: tuple[Column, ...]  # accel xyz, gyro xyz, then mag xyz when the file has a magnetometer
    field_count: int

    @property
    def has_mag(self) -> bool:
        return len(self.axes) == 9


@dataclass
class ImuArrays:
    """One sensor's samples: int64 ns times (strictly increasing), (N, 3) arrays in protocol units."""

    time_ns: np.ndarray
    accel_g: np.ndarray
    gyro_dps: np.ndarray
    mag_gauss: np.ndarray | None


Rows = Iterator[tuple[int, list[str]]]


@contextmanager
def csv_rows(path: Path, display: str) -> Iterator[tuple[list[str], Rows]]:
    """Open a CSV file: yields (header cells stripped, iterator of (line number, fields)).

    Blank lines are passed over. InputError for an unreadable or empty file, a byte that is not
    UTF-8, or a line the csv module rejects (NUL byte, field over its size limit).
    """
    try:
        file = open(path, newline="", encoding="utf-8-sig")  # -sig: drop the BOM spreadsheets write
    except OSError as error:
        raise InputError(f"{display}: cannot read ({error.strerror})") from None
    with file:
        reader = csv.reader(file)

        def rows() -> Rows:
            try:
                for row in reader:
                    if any(cell.strip() for cell in row):
                        yield reader.line_num, row
            except (UnicodeDecodeError, csv.Error) as error:
                raise InputError(f"{display}: unreadable after line {reader.line_num} ({error})") from None

        iterator = rows()
        first = next(iterator, None)
        if first is None:
            raise InputError(f"{display}: empty file (expected a header row, then one row per sample)")
        yield [cell.strip() for cell in first[1]], iterator


def parse_time_ns(text: str, ns_per_unit: int) -> int:
    """Exact decimal `text` times `ns_per_unit`, rounded to an integer; ValueError if not a finite
    number the decimal context can scale (an exponent like 1e999999999 overflows it)."""
    try:
        value = Decimal(text.strip())
        if not value.is_finite():
            raise ValueError(text)
        return int((value * ns_per_unit).to_integral_value(rounding=ROUND_HALF_EVEN))
    except ArithmeticError:  # InvalidOperation (not a number), Overflow
        raise ValueError(text) from None


def layout_from_header(header: list[str], parse_name: Callable[[str], HeaderName | None],
                       name_hint: Callable[[str, str], str], display: str,
                       report: ImportReport, known_extra: Collection[str] = ()) -> ImuLayout:
    """Map header cells to columns; InputError for a missing, doubled or unknown-unit column.

    `parse_name` reads one cell (None: not an IMU column, ignored with a warning);
    `name_hint(quantity, axis)` spells the accepted names for a missing-column message;
    `known_extra` columns (a vendor's barometer) are ignored without a warning.
    """
    found = ", ".join(header)
    columns: dict[tuple[str, str], Column] = {}
    ignored: list[str] = []
    for index, cell in enumerate(header):
        name = parse_name(cell)
        if name is None:
            if cell not in known_extra:
                ignored.append(cell)
            continue
        key = (name.quantity, name.axis)
        if key in columns:
            raise InputError(f"{display}: columns {columns[key].name!r} and {cell!r} both give "
                             f"{'time' if name.quantity == 'time' else name.quantity + '_' + name.axis}; keep one")
        columns[key] = Column(index, cell, _scale(name, cell, display))
    required = [("time", "")] + [(quantity, axis) for quantity in ("accel", "gyro") for axis in AXES]
    missing = [key for key in required if key not in columns]
    if missing:
        quantity, axis = missing[0]
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise InputError(f"{display}: missing column {name_hint(quantity, axis)}{more}; found columns: {found}")
    mag_axes = [axis for axis in AXES if ("mag", axis) in columns]
    if mag_axes and len(mag_axes) < 3:
        absent = [name_hint("mag", axis) for axis in AXES if axis not in mag_axes]
        raise InputError(f"{display}: magnetometer columns must be all three or none; missing {', '.join(absent)}; "
                         f"found columns: {found}")
    if ignored:
        report.warn(f"{display}: ignored columns {', '.join(ignored)}")
    quantities = ("accel", "gyro", "mag") if mag_axes else ("accel", "gyro")
    axes = tuple(columns[(quantity, axis)] for quantity in quantities for axis in AXES)
    return ImuLayout(columns[("time", "")], axes, len(header))


def _scale(name: HeaderName, cell: str, display: str) -> float:
    table = {unit: float(ns) for unit, ns in NS_PER_TIME_UNIT.items()} if name.quantity == "time" \
        else TO_PROTOCOL_UNIT[name.quantity]
    unit = name.unit.lower()
    if unit not in table:
        raise InputError(f"{display}: column {cell!r}: unknown {name.quantity} unit {name.unit!r} "
                         f"(accepted: {', '.join(table)})")
    return table[unit]


def read_imu_rows(rows: Rows, layout: ImuLayout, display: str, report: ImportReport) -> ImuArrays:
    """Stream rows into arrays (8 bytes a value, no per-row objects kept). See the module rules."""
    times = array("q")
    values = array("d")
    time_name = layout.time.name
    ns_per_unit = int(layout.time.scale)
    previous: tuple[int, int, str, list[float]] | None = None  # (time ns, line, time text, values)
    skips: list[str] = []  # this file's first skipped row, for the message when nothing is left

    def skip(line: int, reason: str, detail: str) -> None:
        report.skip(display, line, reason, detail)
        if not skips:
            skips.append(f"line {line}: {detail}")

    for line, row in rows:
        if len(row) != layout.field_count:
            skip(line, "wrong number of fields", f"{len(row)} fields, expected {layout.field_count}: {_excerpt(row)}")
            continue
        time_text = row[layout.time.index].strip()
        try:
            time_ns = parse_time_ns(time_text, ns_per_unit)
        except ValueError:
            skip(line, "not a number", f"column {time_name}: {time_text!r} is not a number")
            continue
        sample, problem = _sample(row, layout.axes)
        if problem:
            skip(line, "not a number", problem)
            continue
        if not 0 <= time_ns <= MAX_TIME_NS:
            raise InputError(f"{display} line {line}: {time_name} {time_text} is outside 0 .. "
                             f"{MAX_TIME_NS / ns_per_unit:.0f} (times are stored as unsigned nanoseconds; "
                             "shift the times or check the unit)")
        if previous is not None and time_ns <= previous[0]:
            if sample == previous[3] and previous[0] - time_ns <= REPEAT_WINDOW_NS:
                skip(line, "repeated sample", f"{time_name} {time_text}: same values as line {previous[1]} "
                                              f"({previous[2]})")
                continue
            raise InputError(f"{display} line {line}: {time_name} {time_text} is not after the previous row's "
                             f"{previous[2]} (line {previous[1]}); a clock that jumps back is refused, not "
                             "reordered: fix the file or split it at this line")
        times.append(time_ns)
        values.extend(sample)
        previous = (time_ns, line, time_text, sample)
    if not times:
        detail = f" (every row was skipped; first: {skips[0]})" if skips else ""
        raise InputError(f"{display}: no samples after the header{detail}")
    table = np.frombuffer(values, dtype=np.float64).reshape(len(times), len(layout.axes))
    return ImuArrays(np.frombuffer(times, dtype=np.int64).copy(), table[:, 0:3].copy(), table[:, 3:6].copy(),
                     table[:, 6:9].copy() if layout.has_mag else None)


def _sample(row: list[str], axes: tuple[Column, ...]) -> tuple[list[float], str]:
    sample = []
    for column in axes:
        text = row[column.index]
        try:
            value = float(text)
        except ValueError:
            return [], f"column {column.name}: {text.strip()!r} is not a number"
        if not math.isfinite(value):
            return [], f"column {column.name}: {text.strip()!r} is not a finite number"
        sample.append(value * column.scale)
    return sample, ""


def _excerpt(row: list[str], limit: int = 80) -> str:
    text = ",".join(row)
    return repr(text if len(text) <= limit else text[:limit] + "...")

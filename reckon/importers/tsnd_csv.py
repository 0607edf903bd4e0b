"""`reckon import tsnd FILE.csv [--venue VENUE.toml] -o session.mcap`: one ATR-Promotions
TSND121/151 log in CSV -> one session MCAP (docs/csv-import.md, "TSND logs").

The file (no header; rows tagged by their first field, values in the device's own units):
  ags,<tick ms>,<acc x>,<acc y>,<acc z>,<gyro x>,<gyro y>,<gyro z>   acc 0.1 mg, gyro 0.01 deg/s
  geo,<tick ms>,<mag x>,<mag y>,<mag z>                              0.1 uT (optional)
This is the layout getty708/atr-tsnd-control reads from logs of ATR's tools
(`ATR/src/log_to_csv.py`: columns sensor, time_ATR, accX..gyroZ; ticks in ms from 00:00; /10000
to g, /100 to deg/s, geo /1e7 to tesla). No vendor file or vendor document was in reach to
confirm it. Rows with another tag (a header, `pres`, `batt`, ...) are counted and reported once.

Times: the tick is ms since midnight of the recording day and wraps at midnight; it is unwrapped
(edge.decoders.tsnd.TickClock, the live decoder's rule) into the sensor's clock, ms since 00:00
of the first row's day. Row rules (skips, repeated samples, time going back) are those of
reckon.importers.tables. Each sample gets the magnetometer reading nearest in time when one lies
within 0.5 s; if any sample has none, the magnetometer is left out, with a warning.

Session: `venue_toml` (a session description, as `reckon edge --venue` takes it) gives venue and
agents; the data belong to `agent_id`'s waist sensor (or its only sensor); agent_id defaults to
the only swimmer. Without one: venue `venue` (25 x 18 m, the swimming paper's pool), one swimmer
`agent_id` (default "swimmer") with one waist sensor `<agent>-waist` (x forward, y left, as the
paper wore it), its rate_hz measured from the data.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from array import array
from collections import Counter
from pathlib import Path

import numpy as np

from edge.decoders.tsnd import DPS_PER_COUNT, G_PER_COUNT, UT_PER_COUNT, TickClock
from protocol.errors import ConfigError
from protocol.keys import check_id
from protocol.session import Agent, AgentKind, Mount, Sensor, Session, load_toml, session_from_dict
from reckon.importers.report import ImportReport
from reckon.importers.tables import Column, ImuArrays, ImuLayout, Rows, csv_rows, read_imu_rows
from reckon.importers.writing import imu_messages, sensor_count, write_messages

log = logging.getLogger(__name__)

SAMPLE_TAG, MAG_TAG = "ags", "geo"
SAMPLE_FIELDS, MAG_FIELDS = 8, 5
NS_PER_MS = 1_000_000
GAUSS_PER_COUNT = UT_PER_COUNT / 100.0  # 1 gauss = 100 uT
MAX_MAG_AGE_NS = 500_000_000  # as ImuBatcher pairs a live magnetometer reading
RATE_TOLERANCE = 0.10  # warn when the data's median rate differs from the TOML rate_hz by more than 10 %
DEFAULT_VENUE = "pool"
DEFAULT_AGENT = "swimmer"
POOL_LENGTH_M, POOL_WIDTH_M = 25.0, 18.0  # the swimming paper's pool

# ags row: tag, tick, acc xyz, gyro xyz; read_imu_rows converts each column by its scale.
SAMPLE_LAYOUT = ImuLayout(
    Column(1, "tick_ms", NS_PER_MS),
    tuple(Column(2 + i, f"acc_{axis} (0.1 mg)", G_PER_COUNT) for i, axis in enumerate("xyz"))
    + tuple(Column(5 + i, f"gyro_{axis} (0.01 deg/s)", DPS_PER_COUNT) for i, axis in enumerate("xyz")),
    SAMPLE_FIELDS)


def import_tsnd_csv(path: Path, output: Path, *, venue_toml: Path | None = None, venue: str = DEFAULT_VENUE,
                    agent_id: str | None = None) -> ImportReport:
    """Import one TSND CSV log into the session MCAP `output`. Raises InputError (file, rows,
    time order) or ConfigError (session description, agent); writes nothing when it raises."""
    path, output = Path(path), Path(output)
    report = ImportReport(output)
    display = str(path)
    mag_rows: list[tuple[int, int, list[str]]] = []  # (line, unwrapped tick ms or -1, fields)
    with csv_rows(path, display) as (first_row, rows):
        data = read_imu_rows(_sample_rows(first_row, rows, mag_rows, display, report), SAMPLE_LAYOUT, display,
                             report)
    data.mag_gauss = _pair_magnetometer(data.time_ns, _magnetometer(mag_rows, display, report), display, report)
    session, agent, sensor = _session(venue_toml, venue, agent_id, data, path)
    _check_rate(display, data, sensor, report)
    report.sensors[sensor.id] = sensor_count(agent.id, data)
    write_messages(output, session, [imu_messages(session.venue.name, agent.id, sensor.id, data,
                                                  report.sensors[sensor.id])])
    log.info("imported %s: %d samples, %d rows skipped", path, len(data.time_ns), report.rows_skipped)
    return report


def _sample_rows(first_row: list[str], rows: Rows, mag_rows: list[tuple[int, int, list[str]]], display: str,
                 report: ImportReport) -> Rows:
    """The `ags` rows with their tick unwrapped (as text, for read_imu_rows); `geo` rows set aside
    with their tick unwrapped on the same clock; other tags counted."""
    clock = TickClock()
    others: Counter[str] = Counter()
    first_other = ""
    # csv_rows hands the first row over as a header; this format has none. It passes blank lines
    # over, so the first row is on line 1 unless the file starts with blank lines.
    for line, row in _chain((1, first_row), rows):
        tag = row[0].strip().lower() if row else ""
        if tag not in (SAMPLE_TAG, MAG_TAG):
            others[tag] += 1
            first_other = first_other or f"line {line}: {','.join(row)[:60]!r}"
            continue
        tick = _tick(row)
        if tick is not None and tick >= 0:
            tick = clock.ms(tick)
        if tag == MAG_TAG:
            mag_rows.append((line, -1 if tick is None else tick, row))
            continue
        if tick is not None and tick >= 0:
            row = [row[0], str(tick), *row[2:]]
        yield line, row
    if others:
        tags = ", ".join(f"{count} x {tag or '(empty)'!r}" for tag, count in others.most_common())
        report.warn(f"{display}: ignored {sum(others.values())} rows not tagged {SAMPLE_TAG} or {MAG_TAG} "
                    f"({tags}; first at {first_other})")


def _chain(first: tuple[int, list[str]], rows: Rows) -> Rows:
    yield first
    yield from rows


def _tick(row: list[str]) -> int | None:
    """The row's tick as an integer, None if it is not one (read_imu_rows then skips the row)."""
    try:
        return int(row[1].strip())
    except (IndexError, ValueError):
        return None


def _magnetometer(rows: list[tuple[int, int, list[str]]], display: str,
                  report: ImportReport) -> tuple[np.ndarray, np.ndarray]:
    """`geo` rows -> (times ns, (M, 3) gauss), in file order; bad rows skipped and counted."""
    times, values = array("q"), array("d")
    for line, tick, row in rows:
        if len(row) != MAG_FIELDS:
            report.skip(display, line, "wrong number of fields", f"{len(row)} fields in a {MAG_TAG} row, "
                                                                 f"expected {MAG_FIELDS}")
            continue
        try:
            reading = [float(cell) * GAUSS_PER_COUNT for cell in row[2:5]]
        except ValueError:
            reading = [math.nan]
        if tick < 0 or not all(math.isfinite(value) for value in reading):
            report.skip(display, line, "not a number", f"{MAG_TAG} row {','.join(row)[:60]!r} is not a tick and "
                                                       "three finite numbers")
            continue
        times.append(tick * NS_PER_MS)
        values.extend(reading)
    return np.frombuffer(times, dtype=np.int64), np.frombuffer(values, dtype=np.float64).reshape(-1, 3)


def _pair_magnetometer(time_ns: np.ndarray, mag: tuple[np.ndarray, np.ndarray], display: str,
                       report: ImportReport) -> np.ndarray | None:
    """Per sample, the nearest magnetometer reading within MAX_MAG_AGE_NS; None (with a warning)
    when the file has none or some sample has none near it."""
    mag_ns, mag_gauss = mag
    if len(mag_ns) == 0:
        return None
    order = np.argsort(mag_ns, kind="stable")
    mag_ns, mag_gauss = mag_ns[order], mag_gauss[order]
    after = np.clip(np.searchsorted(mag_ns, time_ns), 1, len(mag_ns) - 1) if len(mag_ns) > 1 else \
        np.zeros(len(time_ns), dtype=np.int64)
    before = np.maximum(after - 1, 0)
    nearest = np.where(np.abs(mag_ns[before] - time_ns) <= np.abs(mag_ns[after] - time_ns), before, after)
    missing = int(np.count_nonzero(np.abs(mag_ns[nearest] - time_ns) > MAX_MAG_AGE_NS))
    if missing:
        report.warn(f"{display}: {missing} of {len(time_ns)} samples have no {MAG_TAG} reading within "
                    f"{MAX_MAG_AGE_NS / 1e9:g} s; the magnetometer is left out")
        return None
    return mag_gauss[nearest].copy()


def _session(venue_toml: Path | None, venue: str, agent_id: str | None, data: ImuArrays,
             path: Path) -> tuple[Session, Agent, Sensor]:
    source = {"importer": "reckon import tsnd", "file": path.name}
    if venue_toml is None:
        agent_id = check_id(agent_id or DEFAULT_AGENT, "--agent")
        rate_hz = 1e9 / float(np.median(np.diff(data.time_ns))) if len(data.time_ns) > 1 else 1000.0
        sensor_data = {"id": f"{agent_id}-waist", "mount": Mount.WAIST.value, "forward_axis": "+x", "left_axis": "+y",
                       "rate_hz": round(min(max(rate_hz, 1.0), 10_000.0), 3)}
        session = session_from_dict({  # validated like a TOML: ids and values are checked
            "venue": {"name": venue, "court_length_m": POOL_LENGTH_M, "court_width_m": POOL_WIDTH_M},
            "agents": [{"id": agent_id, "kind": AgentKind.SWIMMER.value, "sensors": [sensor_data]}],
            "source": source}, where="reckon import tsnd")
        agent = session.agents[0]
        return session, agent, agent.sensors[0]
    session = load_toml(venue_toml)
    session = dataclasses.replace(session, source={**session.source, **source, "session": Path(venue_toml).name})
    agent = _agent(session, agent_id, venue_toml)
    sensor = agent.sensor(Mount.WAIST) or (agent.sensors[0] if len(agent.sensors) == 1 else None)
    if sensor is None:
        raise ConfigError(f"{venue_toml}: agent {agent.id!r} has no waist sensor and {len(agent.sensors)} others "
                          "(a TSND log is one sensor: give the agent one sensor, or one at mount \"waist\")")
    others = [s.id for a in session.agents for s in a.sensors if s.id != sensor.id]
    if others:
        log.info("%s: only %s is imported from %s; sensors %s get no data", venue_toml, sensor.id, path.name,
                 ", ".join(others))
    return session, agent, sensor


def _agent(session: Session, agent_id: str | None, venue_toml: Path) -> Agent:
    if agent_id is not None:
        try:
            return session.agent(agent_id)
        except KeyError:
            raise ConfigError(f"--agent {agent_id!r}: not in {venue_toml} (agents: "
                              f"{', '.join(a.id for a in session.agents)})") from None
    swimmers = [a for a in session.agents if a.kind is AgentKind.SWIMMER]
    if len(swimmers) != 1:
        raise ConfigError(f"{venue_toml}: {len(swimmers)} swimmer agents; say which one the log belongs to "
                          f"(--agent, one of {', '.join(a.id for a in session.agents)})")
    return swimmers[0]


def _check_rate(display: str, data: ImuArrays, sensor: Sensor, report: ImportReport) -> None:
    if len(data.time_ns) < 3:
        return
    median_s = float(np.median(np.diff(data.time_ns))) * 1e-9
    if abs(1.0 / median_s / sensor.rate_hz - 1.0) > RATE_TOLERANCE:
        report.warn(f"{display}: samples every {median_s * 1e3:.2f} ms ({1.0 / median_s:.1f} Hz) but sensor "
                    f"{sensor.id!r} has rate_hz = {sensor.rate_hz:g}")


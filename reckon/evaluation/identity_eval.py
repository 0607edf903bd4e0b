"""`reckon eval` on a session with camera tracks: who was which track, ours against the paper's.

Measures, per method:
- time correct (the paper's measure): over every camera frame in which an agent is visible (some
  track's truth label names it), the share where the track the method gives that agent is one
  of the tracks showing it (a merged "a+b" track shows both);
- IDF1 (motmetrics): agents as ground truth at their true positions, the method's identified
  track positions as hypotheses named by agent, matched within IDF1_MATCH_M;
- time per update: ours, the wall time of each hop of the live engine (p99); the paper's and ours in
  hindsight, one run over a PAPER_WINDOW_S stretch (what it would redo at each update), the
  paper's extrapolated from the permutations it managed when n! is out of reach.

Ours runs exactly as the hub runs it (reckon/evaluation/reckon_run.py, lockstep over the log).
The paper's regression and eq. 1 constants are fitted on this session's own labels, which
favours the paper (it fitted them on separate labelled data). Ours in hindsight
(hub/identity/hindsight.py: every fragment at once, the regression learnt without labels) is
offline like the paper, and for people on foot only (a chair's seat does not bob with its speed).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from hub.chair.hub import HubSettings
from hub.clocks import ClockOffsets
from hub.identity.engine import IdentitySettings
from hub.identity.hindsight import identify_hindsight
from hub.identity.paper.search import identify
from hub.identity.paper.fragments import training_pairs
from hub.identity.paper.features import PaperModel, fit_model, vertical_acceleration
from protocol.session import AgentKind, Mount
from protocol.session_log import CameraTracks, SessionData
from reckon.evaluation.reckon_run import log_inputs, run_lockstep

IDF1_MATCH_M = 1.0
PAPER_MAX_PERMUTATIONS = 5040  # 7!: about a minute at 10 people; beyond it the search is extrapolated
PAPER_WINDOW_S = 10.0
WHOLE_SESSION_S = 1e7  # clock offsets: the lower envelope over the whole log (offline, no drift to follow)


@dataclass
class IdentityRow:
    method: str
    agents: int
    time_correct_pct: float | None
    idf1: float | None
    update_ms_p99: float | None
    note: str = ""
    per_agent_pct: dict[str, float] = field(default_factory=dict)
    lost_pct: dict[str, float] = field(default_factory=dict)  # share of visible agent-frames lost, by cause (LOSSES)
    naming: dict[str, float] = field(default_factory=dict)  # how long a person's run on a track waits to be named


LOSSES = ("wrong track", "no track: its track in its first 1.5 s", "no track: its track a merge",
          "no track: its track held by another", "no track: its track free")
YOUNG_TRACK_S = 1.5
GAP_FRAMES = 3  # a person's run on a track survives a tracker's gap this short


@dataclass
class IdentityReport:
    session_path: Path
    camera_ids: list[str]
    rows: list[IdentityRow] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def has_cameras(data: SessionData) -> bool:
    return bool(data.cameras)


def evaluate_identity(data: SessionData, path: Path, progress: Callable[[str], None] = lambda _: None,
                      arrivals: list[tuple[int, Any]] | None = None) -> IdentityReport:
    report = IdentityReport(path, sorted(data.cameras))
    agents = [a.id for a in data.session.agents if _body_sensor(a) is not None]
    arrivals = arrivals if arrivals is not None else log_inputs(path)
    progress("identity: ours (the hub's engine over the log)")
    rows, delay_s, live = _ours(data, arrivals, agents)
    report.rows += rows
    report.rows.append(_ceiling(data, agents, delay_s))
    progress("identity: the paper's permutations")
    people_imu = _people(data, arrivals, agents)  # both offline searches read the same waists
    report.rows.append(_paper(data, people_imu, agents, report.notes))
    walkers = [a for a in agents if data.session.agent(a).kind is AgentKind.PEDESTRIAN]
    if walkers:
        progress("identity: ours in hindsight")
        report.rows.append(_hindsight(data, {a: imu for a, imu in people_imu.items() if a in walkers}, walkers,
                                      report.notes, live))
    return report


def _body_sensor(agent: Any) -> Any:
    return agent.sensor(Mount.SEAT) or agent.sensor(Mount.WAIST)


# -- ours ---------------------------------------------------------------------------------------


def _ours(data: SessionData, arrivals: list[tuple[int, Any]],
          agents: list[str]) -> tuple[list[IdentityRow], float, dict[str, dict[str, np.ndarray]]]:
    """(live, refined) rows, the median delay at which the engine scored the camera's bins, and the live
    identities (camera -> agent -> track id at each frame)."""
    identities: list[Any] = []
    hub, _, _ = run_lockstep(data.session, arrivals, HubSettings(corrections=frozenset({"camera"})), identities)
    held: dict[str, list[tuple[int, str, int]]] = {a: [] for a in agents}
    for message in identities:
        if message.agent_id in held:
            held[message.agent_id].append((message.timestamp_ns, message.camera_id, message.track_id))
    timings = np.array(hub.identity.update_s) if hub.identity is not None else np.zeros(0)
    assignment = {camera: {a: _held_at(held[a], camera, tracks.frame_ns) for a in agents}
                  for camera, tracks in data.cameras.items()}
    live = _score("reckon", data, agents, assignment)
    live.naming = _naming(data, agents, assignment)
    live.update_ms_p99 = float(np.percentile(timings, 99) * 1e3) if len(timings) else None
    if hub.identity is not None:
        c = hub.identity.counters
        live.note = (f"live; {c.updates} hops, {c.identity_changes} identity changes, {c.fixes} camera fixes, "
                     f"camera lag {c.lag_bins * 0.1:+.1f} s")
    refined = {camera: _back_filled(held, data.cameras[camera]) for camera, held in assignment.items()}
    hindsight = _score("reckon", data, agents, refined)
    hindsight.update_ms_p99 = live.update_ms_p99
    hindsight.note = "refined: a track's identity also holds back to where the track began (offline, like the paper)"
    delays = hub.identity.delays_s if hub.identity is not None else ()
    return ([live, hindsight], float(np.median(delays)) if len(delays) else IdentitySettings().delay_s,
            assignment)


def _back_filled(held: dict[str, np.ndarray], tracks: CameraTracks) -> dict[str, np.ndarray]:
    """Each identity extended back over the frames before it was decided, while its track was already
    there, nobody else held it and the agent held nothing else."""
    frame_of_row = np.searchsorted(tracks.frame_ns, tracks.time_ns)
    present: dict[int, set[int]] = {}
    for f, track in zip(frame_of_row, tracks.track_id):
        present.setdefault(int(track), set()).add(int(f))
    out = {a: np.array([t if f in present.get(int(t), ()) else 0 for f, t in enumerate(ids)], dtype=np.int64)
           for a, ids in held.items()}  # a track the camera no longer shows is not held
    taken = np.zeros((len(tracks.frame_ns),), dtype=object)
    for f in range(len(taken)):
        taken[f] = {int(ids[f]) for ids in out.values() if ids[f]}
    for agent, ids in out.items():
        for f in range(len(ids) - 1, 0, -1):
            track = int(ids[f])
            if track and not ids[f - 1] and (f - 1) in present.get(track, ()) and track not in taken[f - 1]:
                ids[f - 1] = track
                taken[f - 1].add(track)
    return out


def _rows_by_frame(tracks: CameraTracks) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends): frame f's rows are starts[f]:ends[f] (rows are in frame order)."""
    frame_of_row = np.searchsorted(tracks.frame_ns, tracks.time_ns)
    frames = np.arange(len(tracks.frame_ns))
    return np.searchsorted(frame_of_row, frames), np.searchsorted(frame_of_row, frames, side="right")


def _held_at(changes: list[tuple[int, str, int]], camera: str, frame_ns: np.ndarray) -> np.ndarray:
    """The track id the agent held at each frame time (0: none)."""
    mine = [(t, track) for t, cam, track in changes if cam == camera]
    if not mine:
        return np.zeros(len(frame_ns), dtype=np.int64)
    times = np.array([t for t, _ in mine], dtype=np.int64)
    tracks = np.array([track for _, track in mine], dtype=np.int64)
    index = np.searchsorted(times, frame_ns, side="right") - 1
    return np.where(index >= 0, tracks[np.maximum(index, 0)], 0)


def _naming(data: SessionData, agents: list[str], assignment: dict[str, dict[str, np.ndarray]]) -> dict[str, float]:
    """How long a method waits to name a person's run on a track: a run starts when a track starts showing
    a person (a new track, a swap, a merge) and ends when it stops (gaps up to GAP_FRAMES bridged); its
    wait is until the method first holds that track for that person within the run, or the whole run
    if it never does. 99 % of the time correct needs about runs per minute x mean wait < 0.6 s."""
    waits: list[float] = []
    first_frame = 0
    seconds = 0.0
    for camera, tracks in data.cameras.items():
        if tracks.person_id is None or camera not in assignment or len(tracks.frame_ns) < 2:
            continue
        held = assignment[camera]
        frame_of_row = np.searchsorted(tracks.frame_ns, tracks.time_ns)
        runs: dict[tuple[int, str], list[list[int]]] = {}
        for f, track, label in zip(frame_of_row.tolist(), tracks.track_id.tolist(), tracks.person_id):
            for person in str(label).split("+"):
                if person in held:
                    spans = runs.setdefault((int(track), person), [])
                    if spans and spans[-1][1] >= f - GAP_FRAMES:
                        spans[-1][1] = f
                    else:
                        spans.append([f, f])
        frame_s = float(np.median(np.diff(tracks.frame_ns))) * 1e-9
        seconds += (tracks.frame_ns[-1] - tracks.frame_ns[0]) * 1e-9
        for (track, person), spans in runs.items():
            for f0, f1 in spans:
                named = np.flatnonzero(held[person][f0:f1 + 1] == track)
                waits.append((named[0] if len(named) else f1 - f0 + 1) * frame_s)
                first_frame += bool(len(named)) and named[0] == 0
    if not waits:
        return {}
    w = np.array(waits)
    return {"runs_per_agent_minute": len(w) / max(len(agents), 1) / max(seconds / 60.0, 1e-9),
            "first_frame_pct": 100.0 * first_frame / len(w), "p50_s": float(np.median(w)),
            "p90_s": float(np.percentile(w, 90)), "mean_s": float(w.mean())}


def _ceiling(data: SessionData, agents: list[str], latency_s: float) -> IdentityRow:
    """What identifying from motion can reach live at best: an oracle that knows who every track shows,
    but names a track for a person only once it has shown them for `latency_s` (our engine's median
    delay: it scores a camera bin once the agents' data for it has arrived, and then still needs
    evidence). Each birth, swap or merge of the tracker costs it latency_s per person involved."""
    assignment: dict[str, dict[str, np.ndarray]] = {}
    for camera, tracks in data.cameras.items():
        if tracks.person_id is None:
            continue
        held = {a: np.zeros(len(tracks.frame_ns), dtype=np.int64) for a in agents}
        since: dict[tuple[int, str], int] = {}  # (track, person) -> first frame of its current run
        starts, ends = _rows_by_frame(tracks)
        for f, frame_ns in enumerate(tracks.frame_ns):
            shown = {(int(tracks.track_id[r]), a) for r in range(starts[f], ends[f])
                     for a in str(tracks.person_id[r]).split("+") if a}
            # sorted: a person shown by two tracks goes to the lower track id, whatever the string hash seed
            since = {pair: since.get(pair, int(frame_ns)) for pair in sorted(shown)}
            for (track, a), first_ns in since.items():
                if a in held and frame_ns - first_ns >= latency_s * 1e9 and held[a][f] == 0:
                    held[a][f] = track
        assignment[camera] = held
    row = _score("ceiling", data, agents, assignment)
    row.naming = _naming(data, agents, assignment)
    row.note = (f"an oracle that names a track for a person {latency_s:.1f} s after it starts showing them "
                "(the engine's median delay): the most motion evidence can reach live")
    return row


# -- the paper ----------------------------------------------------------------------------------


def _people(data: SessionData, arrivals: list[tuple[int, Any]], agents: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each agent's body IMU on the venue clock (offset from arrival stamps, as the hub does)."""
    clocks = ClockOffsets(window_s=WHOLE_SESSION_S)
    for _, message in arrivals:
        if message.DESCRIPTOR.name == "ImuBatch" and len(message.sample_offset_ns):
            clocks.observe(message.sensor_id, message.timestamp_ns + message.sample_offset_ns[-1], message.received_ns)
    out = {}
    for agent_id in agents:
        sensor = _body_sensor(data.session.agent(agent_id))
        series = data.imu.get(sensor.id)
        if series is not None:
            out[agent_id] = (series.time_ns + clocks.offset_ns(sensor.id), series.accel_g)
    return out


def _verticals(people_imu: dict[str, tuple[np.ndarray, np.ndarray]],
               frame_ns: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each wearer's vertical acceleration at the frame times, as both identification searches take it."""
    return {a: (frame_ns, vertical_acceleration(t, acc, frame_ns)) for a, (t, acc) in people_imu.items()}


def _paper(data: SessionData, people_imu: dict[str, tuple[np.ndarray, np.ndarray]], agents: list[str],
           notes: list[str]) -> IdentityRow:
    assignment: dict[str, dict[str, np.ndarray]] = {}
    elapsed, tried, needed, stopped = 0.0, 0, 1, ""
    models: dict[str, PaperModel] = {}
    for camera, tracks in data.cameras.items():
        if tracks.person_id is None:
            notes.append(f"{camera}: no truth labels; the paper's regression cannot be fitted and nothing is scored")
            continue
        verticals = _verticals(people_imu, tracks.frame_ns)
        model = _fit(tracks, verticals, notes, camera)
        if model is None:
            continue
        models[camera] = model
        started = time.perf_counter()
        result = identify(tracks, verticals, model, PAPER_MAX_PERMUTATIONS)
        elapsed += time.perf_counter() - started
        tried, needed = result.permutations_tried, result.permutations_needed
        stopped = result.reason
        assignment[camera] = {a: ids for a, ids in result.assignment(tracks.frame_ns).items()}
        notes.append(f"{camera}: the paper's regression r = {model.correlation:.2f} (the paper: 0.91), "
                     f"slope {model.slope_g_per_mps:.3f} g per m/s, Ave {model.ave_abs_error_g:.3f} g, "
                     f"SD {model.sd_abs_error_g:.3f} g")
    row = _score("paper", data, agents, assignment)
    row.update_ms_p99 = _paper_update_ms(data, people_imu, models)
    row.note = (f"{tried} of {needed:.3g} permutations" + (" (stopped at the budget)" if stopped else "")
                + f", whole session {elapsed:.1f} s" + (", update time extrapolated to n!" if stopped else ""))
    return row


def _hindsight(data: SessionData, people_imu: dict[str, tuple[np.ndarray, np.ndarray]], walkers: list[str],
               notes: list[str], live: dict[str, dict[str, np.ndarray]]) -> IdentityRow:
    """Ours offline: every fragment of each camera at once, the regression learnt from the session (no labels),
    the live engine's identities as evidence too. people_imu: the walkers' (`_people`)."""
    assignment: dict[str, dict[str, np.ndarray]] = {}
    for camera, tracks in data.cameras.items():
        result = identify_hindsight(tracks, _verticals(people_imu, tracks.frame_ns), held=live.get(camera))
        assignment[camera] = result.assignment(tracks.frame_ns)
        solution, m = result.solution, result.solution.model
        notes.append(f"{camera}, ours in hindsight: learnt without labels slope {m.slope_g_per_mps:.3f} g per m/s, "
                     f"Ave {m.ave_abs_error_g:.3f} g, SD {m.sd_abs_error_g:.3f} g (r = {m.correlation:.2f}), the likeliest "
                     f"of the assignments at round {solution.iterations}{'' if solution.converged else ' (not converged)'}; "
                     f"LP relaxation gap {100 * solution.relaxation_gap:.2f} %")
    row = _score("hindsight", data, walkers, assignment)
    camera, tracks = next(iter(sorted(data.cameras.items())))
    window = _tail(tracks, PAPER_WINDOW_S)
    verticals = _verticals(people_imu, window.frame_ns)
    started = time.perf_counter()  # as the paper's: the search, not the features
    identify_hindsight(window, verticals)
    row.update_ms_p99 = (time.perf_counter() - started) * 1e3
    row.note = (f"every fragment at once, regression learnt without labels, the live identities as evidence "
                f"(offline, like the paper); update: one run over the last {PAPER_WINDOW_S:.0f} s")
    return row


def _fit(tracks: CameraTracks, verticals: dict[str, tuple[np.ndarray, np.ndarray]], notes: list[str],
         camera: str) -> PaperModel | None:
    speeds, values, ids = training_pairs(tracks, tracks.person_id, verticals, PaperModel(0, 0, 0, 0).window_s)
    try:
        return fit_model(speeds, values, ids)
    except ValueError as error:
        notes.append(f"{camera}: the paper's regression could not be fitted ({error})")
        return None


def _paper_update_ms(data: SessionData, people_imu: dict[str, tuple[np.ndarray, np.ndarray]],
                     models: dict[str, PaperModel]) -> float | None:
    """One run of the paper's search over the last PAPER_WINDOW_S of the first camera; extrapolated to n!."""
    camera, tracks = next(iter(sorted(data.cameras.items())))
    if camera not in models or not people_imu:
        return None
    window = _tail(tracks, PAPER_WINDOW_S)
    verticals = _verticals(people_imu, window.frame_ns)
    started = time.perf_counter()
    result = identify(window, verticals, models[camera], PAPER_MAX_PERMUTATIONS)
    seconds = time.perf_counter() - started
    return seconds * 1e3 * result.permutations_needed / max(result.permutations_tried, 1)


def _tail(tracks: CameraTracks, seconds: float) -> CameraTracks:
    start = tracks.frame_ns[-1] - int(seconds * 1e9)
    rows = tracks.time_ns >= start
    return CameraTracks(tracks.camera_id, tracks.frame_ns[tracks.frame_ns >= start], tracks.time_ns[rows],
                        tracks.track_id[rows], tracks.x_m[rows], tracks.y_m[rows],
                        None if tracks.height_m is None else tracks.height_m[rows], tracks.position_sd_m,
                        None if tracks.person_id is None else tracks.person_id[rows])


# -- scoring ------------------------------------------------------------------------------------


def _score(method: str, data: SessionData, agents: list[str], assignment: dict[str, dict[str, np.ndarray]]) -> IdentityRow:
    """Time correct and IDF1 of `assignment`: camera -> agent -> track id held at each frame."""
    import motmetrics

    correct = {a: 0 for a in agents}
    visible = {a: 0 for a in agents}
    lost = dict.fromkeys(LOSSES, 0)
    accumulator = motmetrics.MOTAccumulator(auto_id=True)
    number = {a: k + 1 for k, a in enumerate(agents)}
    for camera, tracks in data.cameras.items():
        if tracks.person_id is None or camera not in assignment:
            continue
        held = assignment[camera]
        starts, ends = _rows_by_frame(tracks)
        truth_xy = {a: _truth_at(data, a, tracks.frame_ns) for a in agents}
        ids, first_row = np.unique(tracks.track_id, return_index=True)
        born_ns = dict(zip(ids.tolist(), tracks.time_ns[first_row].tolist()))
        for f in range(len(tracks.frame_ns)):
            rows = range(starts[f], ends[f])
            shown = {a: {int(tracks.track_id[r]) for r in rows if a in str(tracks.person_id[r]).split("+")} for a in agents}
            where = {int(tracks.track_id[r]): (tracks.x_m[r], tracks.y_m[r]) for r in rows}
            merged = {int(tracks.track_id[r]) for r in rows if "+" in str(tracks.person_id[r])}
            holding = {int(held[a][f]) for a in agents if a in held and len(held[a]) > f} - {0}
            gt, hyp, hyp_xy = [], [], []
            for a in agents:
                track = int(held.get(a, np.zeros(0))[f]) if a in held and len(held[a]) > f else 0
                if shown[a]:
                    visible[a] += 1
                    correct[a] += track in shown[a]
                    if track not in shown[a]:
                        lost[_cause(track, shown[a], merged, holding, born_ns, int(tracks.frame_ns[f]))] += 1
                    gt.append(a)
                if track in where:
                    hyp.append(a)
                    hyp_xy.append(where[track])
            gt_xy = np.array([truth_xy[a][f] for a in gt]).reshape(-1, 2)
            distances = motmetrics.distances.norm2squared_matrix(gt_xy, np.array(hyp_xy).reshape(-1, 2),
                                                                 max_d2=IDF1_MATCH_M**2)
            accumulator.update([number[a] for a in gt], [number[a] for a in hyp], distances)
    seen = sum(visible.values())
    per_agent = {a: 100.0 * correct[a] / visible[a] for a in agents if visible[a]}
    idf1 = None
    if seen:
        summary = motmetrics.metrics.create().compute(accumulator, metrics=["idf1"], name=method)
        idf1 = float(summary["idf1"].iloc[0])
    return IdentityRow(method, len(agents), 100.0 * sum(correct.values()) / seen if seen else None, idf1, None,
                       per_agent_pct=per_agent, lost_pct={k: 100.0 * n / seen for k, n in lost.items()} if seen else {})


def _cause(track: int, shown: set[int], merged: set[int], holding: set[int], born_ns: dict, frame_ns: int) -> str:
    """Why an agent visible on `shown` was not correctly identified at this frame (one of LOSSES)."""
    if track:
        return LOSSES[0]
    if min(frame_ns - born_ns[t] for t in shown) < YOUNG_TRACK_S * 1e9:
        return LOSSES[1]
    if shown & merged:
        return LOSSES[2]
    return LOSSES[3] if shown & holding else LOSSES[4]


def _truth_at(data: SessionData, agent_id: str, frame_ns: np.ndarray) -> np.ndarray:
    truth = data.truth.get(agent_id)
    if truth is None:
        return np.full((len(frame_ns), 2), np.nan)
    return np.column_stack([np.interp(frame_ns, truth.time_ns, truth.x_m), np.interp(frame_ns, truth.time_ns, truth.y_m)])


# -- output -------------------------------------------------------------------------------------


def _r(value: float | None, digits: int = 2) -> float | None:
    return None if value is None or not math.isfinite(value) else round(value, digits)


def to_json(report: IdentityReport) -> list[dict[str, Any]]:
    return [{"method": row.method, "agents": row.agents, "time_correct_pct": _r(row.time_correct_pct),
             "idf1": _r(row.idf1, 4), "update_ms_p99": _r(row.update_ms_p99, 3), "note": row.note,
             "per_agent_pct": {a: _r(v) for a, v in row.per_agent_pct.items()},
             "lost_pct": {k: _r(v) for k, v in row.lost_pct.items()},
             "naming": {k: _r(v, 3) for k, v in row.naming.items()}} for row in report.rows]


def to_table(report: IdentityReport) -> str:
    lines = [f"camera identity, cameras {', '.join(report.camera_ids)}",
             f"{'method':9} {'agents':>6} {'time correct %':>15} {'IDF1':>6} {'update p99 ms':>14}  note"]
    for row in report.rows:
        pct = "-" if row.time_correct_pct is None else f"{row.time_correct_pct:.1f}"
        idf1 = "-" if row.idf1 is None else f"{row.idf1:.3f}"
        ms = "-" if row.update_ms_p99 is None else f"{row.update_ms_p99:.3g}"
        lines.append(f"{row.method:9} {row.agents:>6} {pct:>15} {idf1:>6} {ms:>14}  {row.note}")
        if row.naming:
            n = row.naming
            lines.append(" " * 9 + f"naming: {n['runs_per_agent_minute']:.1f} runs per agent-minute, "
                         f"{n['first_frame_pct']:.0f} % in their first frame, wait p50 {n['p50_s']:.2f} s, "
                         f"p90 {n['p90_s']:.2f} s, mean {n['mean_s']:.2f} s")
        if row.lost_pct:
            lines.append(" " * 9 + "lost: " + ", ".join(f"{k} {v:.1f} %" for k, v in row.lost_pct.items()))
    lines += [f"  {note}" for note in report.notes]
    return "\n".join(lines)


SCALING_AGENTS = (3, 6, 10, 20, 50)


def scaling(seed: int = 1, duration_s: float = 30.0, progress: Callable[[str], None] = lambda _: None,
            folder: Path | None = None) -> list[IdentityRow]:
    """Time per update as agents grow: the room simulator at 3 ... 50 wearers, ours and the paper's."""
    import tempfile

    from protocol.session_log import read_session
    from sim_devices.room import simulate_room

    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for people in SCALING_AGENTS:
            path = Path(folder or scratch) / f"room-{people}.mcap"
            progress(f"scaling: {people} wearers, simulating {duration_s:.0f} s")
            simulate_room(path, seed=seed, people=people, duration_s=duration_s)
            report = evaluate_identity(read_session(path), path, progress)
            rows += [row for row in report.rows if not row.note.startswith("refined")]
    return rows

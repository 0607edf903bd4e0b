"""Edge and hub processes on loopback Zenoh: one run of the live pipeline, and the hub's recording read back.

`play` starts a `reckon hub` and one `reckon edge` per agent of a game, all from a common
`--start-at`, and collects chosen streams in this process meanwhile; `hub_timeline` reads when
the hub took its inputs and published its outputs from its own recording.
"""

from __future__ import annotations

import os
import queue
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message

from protocol import bus as wire
from protocol import keys
from protocol.errors import ReckonError
from protocol.session_log import iter_records, read_description
from reckon.bench.children import Child, Exited, cli_command, system_busy_s
from reckon.transport.bus import Received, Subscription, free_endpoint, open_session, wait_for_peers, zenoh_config

START_S_PER_EDGE = 0.5  # the least start-up allowance per edge process (imports, numba cache, zenoh)
# An edge started after the common start replays what it missed as fast as it can, and that burst
# queues in the hub: the latency would measure the start-up, not the pipeline (10 edges 4 s late
# put p99 at 260-430 ms against 10-70 ms once they ran in step). So a late start is done again.
START_ATTEMPTS = 3
EXIT_TIMEOUT_S = 300.0
POLL_S = 0.05  # how often the processes' peak RSS is read, and what arrived here is taken, while they run
SUBSCRIPTION_CAPACITY = 16384  # samples between two takes: ~1,300 a second arrive with 10 chairs
HUB_INPUTS = ("imu", "clock", "beacon", "pose/edge", "event", "fix", "field")


@dataclass
class Play:
    """What one run of the live pipeline left: times (ns, wall clock), processes, what this process saw."""

    start_at_ns: int
    edges_up_ns: int
    edges_done_ns: int
    hub: Exited
    edges: dict[str, Exited]
    recording: Path
    hub_summary: str
    cpu_at_start: dict[str, float]  # "hub" and agent ids: CPU seconds used before start_at (start-up)
    system_busy_s: float  # CPU seconds the whole machine was busy from start_at to the hub's exit
    own_cpu_s: float  # of which this process (watching)
    received: list[Received] = field(default_factory=list)
    late_starts: list[float] = field(default_factory=list)  # seconds late, of each attempt given up
    start_allowance_s: float = 0.0  # of the attempt kept


class _Late(Exception):
    """The edges were up only after their common start, by `late_s`."""

    def __init__(self, late_s: float):
        super().__init__(f"the edges were up {late_s:.3f} s after their common start")
        self.late_s = late_s


def start_allowance_s(edges: int, startup_cpu_s: float, cores: int) -> float:
    """Seconds from launching the edges to their common start: each edge's start-up CPU
    (`startup_cpu_s`, measured) spread over the cores, twice over for opening Zenoh, reading the
    log and the machine's noise, and at least START_S_PER_EDGE an edge."""
    return 1.0 + max(START_S_PER_EDGE * edges, 2.0 * edges * startup_cpu_s / max(1, cores))


def play(game: Path, folder: Path, speed: float, selectors: tuple[str, ...] = (), startup_cpu_s: float = 0.0) -> Play:
    """Run a hub and one `reckon edge` per agent of `game` at `speed`; collect `selectors` meanwhile.

    Peers do not relay for each other here (no gossip), so the edges connect to the hub and to
    this process; this process sends nothing. The edges wait for a common `--start-at`, later
    than their start-up (start_allowance_s), so all of them run from the same instant; when they
    are not all up by then, everything is stopped and started again with twice the allowance
    (`late_starts` counts those), at most START_ATTEMPTS times.
    """
    session = read_description(game)
    allowance_s = start_allowance_s(len(session.agents), startup_cpu_s, len(os.sched_getaffinity(0)))
    late: list[float] = []
    for _ in range(START_ATTEMPTS):
        try:
            run = _play_once(game, session, folder, speed, selectors, allowance_s)
        except _Late as error:
            late.append(error.late_s)
            allowance_s *= 2
            continue
        run.late_starts = late
        run.start_allowance_s = allowance_s
        return run
    raise ReckonError(f"bench: the edges were not up by their common start in {START_ATTEMPTS} attempts "
                      f"(late by {', '.join(f'{s:.1f}' for s in late)} s; last allowance {allowance_s / 2:.1f} s): "
                      "is the machine busy?")


def _play_once(game: Path, session: Any, folder: Path, speed: float, selectors: tuple[str, ...],
               allowance_s: float) -> Play:
    venue = session.venue.name
    logs = folder / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    hub_endpoint, bench_endpoint = free_endpoint(), free_endpoint()
    recording = folder / "hub.mcap"
    recording.unlink(missing_ok=True)  # an attempt given up leaves one
    hub = Child("hub", cli_command("hub", "--venue", str(game), "--listen", hub_endpoint, "-o", str(recording)),
                logs / "hub.log")
    edges: dict[str, Child] = {}
    received: list[Received] = []
    try:
        with open_session(zenoh_config(listen=[bench_endpoint], connect=[hub_endpoint])) as bus:
            wait_for_peers(bus, wire.alive_selector(venue, wire.Role.HUB), 1, 60.0)
            subscription = Subscription(bus, list(selectors), capacity=SUBSCRIPTION_CAPACITY) if selectors else None
            try:
                start_at = time.time() + allowance_s
                for agent in session.agents:
                    edges[agent.id] = Child(f"edge {agent.id}", cli_command(
                        "edge", "--agent", agent.id, "--source", f"mcap://{game}", "--speed", repr(float(speed)),
                        "--start-at", f"{start_at:.6f}", "--connect", hub_endpoint, "--connect", bench_endpoint),
                        logs / f"edge-{agent.id}.log")
                wait_for_peers(bus, wire.alive_selector(venue, wire.Role.EDGE), len(edges), 60.0)
                edges_up_ns = time.time_ns()
                if edges_up_ns > start_at * 1e9:
                    raise _Late(edges_up_ns * 1e-9 - start_at)
                time.sleep(max(0.0, start_at - 0.05 - time.time()))  # everyone is idle, waiting for start_at
                cpu_at_start = {name: child.cpu_s() for name, child in [("hub", hub), *edges.items()]}
                busy_at_start, own_at_start = system_busy_s(), time.process_time()
                while True:
                    hub.poll()  # notes its peak RSS so far
                    if all([edge.poll() is not None for edge in edges.values()]):  # a list: poll every one
                        break
                    _collect(subscription, received, POLL_S)
                edges_done_ns = time.time_ns()
                hub.interrupt()  # the edges' flush barrier answered: the hub holds all their samples
                while hub.poll() is None:
                    _collect(subscription, received, POLL_S)
                busy_s, own_s = system_busy_s() - busy_at_start, time.process_time() - own_at_start
                while _collect(subscription, received, 0.2):
                    pass
            finally:
                if subscription is not None:
                    subscription.close()
    finally:
        children = [*edges.values(), hub]
        for child in children:
            child.interrupt()
        for child in children:
            child.reap(EXIT_TIMEOUT_S)
    for child in children:
        if child.exited is not None and child.exited.returncode != 0:
            raise ReckonError(f"bench: {child.name} exited with {child.exited.returncode}; see {child.log_path}")
    exited = {agent_id: edge.reap(0) for agent_id, edge in edges.items()}
    hub_exited = hub.reap(0)
    return Play(int(start_at * 1e9), edges_up_ns, edges_done_ns, hub_exited, exited, recording,
                hub_summary_line((logs / "hub.log").read_text(errors="replace")), cpu_at_start, busy_s, own_s, received)


def hub_summary_line(log_text: str) -> str:
    """The hub's closing summary line (reckon/processes/hub.py HubSummary) in its log, without the
    indented lines after it (a beacon's, a walker's, a swimmer's); "" if it never wrote one."""
    lines = [line for line in log_text.splitlines() if line.startswith("hub ")]
    return lines[-1] if lines else ""


def _collect(subscription: Subscription | None, into: list[Received], duration_s: float) -> int:
    """Sleep `duration_s`, then move what arrived meanwhile into `into`; how many came.

    The subscription's drain threads stamp each arrival as it happens; taking the samples in
    batches keeps this process from waking up for every one (it shares the cores it measures).
    """
    time.sleep(duration_s)
    count = 0
    while subscription is not None:
        try:
            item = subscription.get(timeout=0)
        except queue.Empty:
            break
        if item is None:
            break
        into.append(item)
        count += 1
    return count


def stream_of(topic: str) -> str:
    _, _, stream, sub = keys.parse(topic)
    return f"{stream}/{sub}" if stream == "pose" else stream


def hub_timeline(recording: Path) -> dict[str, Any]:
    """Log times of the hub's recording: inputs carry their arrival, outputs their publication."""
    problems: list[str] = []
    streams: dict[int, str] = {}
    inputs: dict[str, int] = {}
    outputs: dict[str, int] = {}
    first_input = last_input = last_live = 0
    for record in iter_records(recording, problems):
        if isinstance(record, Channel):
            streams[record.id] = stream_of(record.topic)
        elif isinstance(record, Message):
            stream = streams[record.channel_id]
            if stream in HUB_INPUTS:
                inputs[stream] = inputs.get(stream, 0) + 1
                first_input = record.log_time if not first_input else min(first_input, record.log_time)
                last_input = max(last_input, record.log_time)
            else:
                outputs[stream] = outputs.get(stream, 0) + 1
                if stream == "pose/live":
                    last_live = max(last_live, record.log_time)
    if problems or not last_live:
        raise ReckonError(f"bench: {recording} has no live pose{'; ' + problems[0] if problems else ''}")
    return {"first_input_ns": first_input, "last_input_ns": last_input, "last_live_ns": last_live,
            "inputs": inputs, "outputs": outputs}

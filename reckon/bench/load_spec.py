"""The load of `reckon bench load`: its settings, its venue of courts, and the chairs' motion and contacts.

The venue: 50 courts of 10 chairs (28 x 15 m, a FIBA court each, gaps of 4 m), one hub. Ten chairs
per court keeps each chair's neighbours, and so its contact and beacon rates, those of a real game;
one hub for all 500 is the hard case: one subscription, one collision-pairing watermark over
every chair. With `hubs` > 1 the courts are sharded, in blocks, into that many venues (`load-1`,
`load-2`, ...: each its own key space and venue file), one hub each, as a hall with more chairs
than one core can take would run. Motion is three sinusoids per axis and chair (0.02-0.10 Hz, up to ~5 m/s), computed
for all chairs at once each tick; a contact is two chairs of a court coming within 0.9 m.
Edges are not phase-aligned: chair i publishes in slot i % PHASES of each pose period.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from protocol.errors import ReckonError
from protocol.session import Agent, Beacon, Mount, Sensor, Session, Venue

VENUE = "load"
COURT_AGENTS = 10
COURTS_PER_ROW = 10
COURT_LENGTH_M, COURT_WIDTH_M, COURT_GAP_M = 28.0, 15.0, 4.0
BASKET_INSET_M = 1.575  # FIBA: backboard 1.2 m in, ring centre 0.375 m further
MAX_AGENTS = 2500  # 25 rows of courts: the venue file's 500 m limit
PHASES = 10  # publishing slots per pose period
CONTACT_M = 0.9  # two chair discs of 0.45 m touching (sim_devices/wheelchair)
POSE_VARIANCE_M2 = 0.25  # what the edges report: a few metres of drift are corrected every 10-30 s
HEADING_VARIANCE_RAD2 = 0.01
DRIFT_M_PER_TICK = 0.02  # random walk of each estimate: 0.14 m/sqrt(s) at 50 Hz
BEACON_HEARD_HZ = 7.0  # 10 Hz advertising x 0.7 scan efficiency (sim_devices/wheelchair/params.py)
PATH_LOSS_EXPONENT, RSSI_SD_DB, SENSITIVITY_DBM, TX_POWER_DBM = 2.2, 4.5, -95.0, -59.0
BEACON_HEIGHT_M, RECEIVER_HEIGHT_M = 2.9, 0.5


@dataclass(frozen=True)
class LoadSpec:
    agents: int = 500
    rate_hz: float = 50.0
    duration_s: float = 60.0
    seed: int = 1
    start_at_ns: int = 0  # wall clock of the first pose period
    hub_endpoints: tuple[str, ...] = ()  # one per hub
    watcher_endpoint: str = ""
    hubs: int = 1

    def __post_init__(self) -> None:
        if not 2 <= self.agents <= MAX_AGENTS:
            raise ReckonError(f"bench load: --agents {self.agents} must be 2-{MAX_AGENTS} (courts of {COURT_AGENTS})")
        if not 1.0 <= self.rate_hz <= 200.0:
            raise ReckonError(f"bench load: --rate {self.rate_hz:g} Hz must be 1-200")
        if self.duration_s < 1.0:
            raise ReckonError(f"bench load: --duration {self.duration_s:g} s must be at least 1")
        if not 1 <= self.hubs <= self.courts:
            raise ReckonError(f"bench load: --hubs {self.hubs} must be 1-{self.courts} (a hub takes whole courts: "
                              f"{self.agents} chairs are {self.courts} courts of {COURT_AGENTS})")

    @property
    def courts(self) -> int:
        return -(-self.agents // COURT_AGENTS)

    def shard(self, index: int) -> int:
        """The hub (0-based) of chair `index`: its court's block."""
        return (index // COURT_AGENTS) * self.hubs // self.courts

    def venue(self, shard: int) -> str:
        return VENUE if self.hubs == 1 else f"{VENUE}-{shard + 1}"

    def venues(self) -> list[str]:
        return [self.venue(k) for k in range(self.hubs)]

    @property
    def period_ns(self) -> int:
        return int(round(1e9 / self.rate_hz))

    @property
    def ticks(self) -> int:
        return int(self.duration_s * self.rate_hz)

    def agent_id(self, index: int) -> str:
        return f"c{index // COURT_AGENTS:02d}-{index % COURT_AGENTS}"

    def phase_ns(self) -> np.ndarray:
        return (np.arange(self.agents) % PHASES) * (self.period_ns // PHASES)


# ---------------------------------------------------------------------------------------------
# The venue and the chairs' motion


def court_origins(agents: int) -> np.ndarray:
    courts = -(-agents // COURT_AGENTS)
    index = np.arange(courts)
    return np.stack([(index % COURTS_PER_ROW) * (COURT_LENGTH_M + COURT_GAP_M),
                     (index // COURTS_PER_ROW) * (COURT_WIDTH_M + COURT_GAP_M)], axis=1)


def load_session(spec: LoadSpec, shard: int | None = None) -> Session:
    """The venue of every chair (`shard` None), or of one hub's courts."""
    origins = court_origins(spec.agents)
    courts = [c for c in range(len(origins)) if shard is None or c * spec.hubs // spec.courts == shard]
    beacons = tuple(Beacon(f"c{c:02d}-goal-{end}", float(origins[c, 0] + inset),
                           float(origins[c, 1] + COURT_WIDTH_M / 2), 1.0, TX_POWER_DBM, BEACON_HEIGHT_M)
                    for c in courts for end, inset in (("a", BASKET_INSET_M), ("b", COURT_LENGTH_M - BASKET_INSET_M)))
    rows = -(-len(origins) // COURTS_PER_ROW)
    venue = Venue(VENUE if shard is None else spec.venue(shard), min(len(origins), COURTS_PER_ROW) * (
        COURT_LENGTH_M + COURT_GAP_M), rows * (COURT_WIDTH_M + COURT_GAP_M), beacons)
    agents = []
    for i in range(spec.agents):
        if shard is not None and spec.shard(i) != shard:
            continue
        agent_id = spec.agent_id(i)
        agents.append(Agent(agent_id, sensors=(
            Sensor(f"{agent_id}-l", Mount.LEFT_WHEEL, spin_axis="+z"), Sensor(f"{agent_id}-r", Mount.RIGHT_WHEEL,
                                                                               spin_axis="-z"),
            Sensor(f"{agent_id}-s", Mount.SEAT, forward_axis="+x", left_axis="+y"))))
    return Session(venue, tuple(agents), {"bench": "load", **asdict(spec)})


class Motion:
    """Every chair's true position at a time: its court's centre plus three sinusoids per axis."""

    def __init__(self, agents: int, rng: np.random.Generator):
        centre = court_origins(agents)[np.arange(agents) // COURT_AGENTS] + [COURT_LENGTH_M / 2, COURT_WIDTH_M / 2]
        self.centre = centre  # agents x 2
        reach = np.array([COURT_LENGTH_M / 2 - 1.0, COURT_WIDTH_M / 2 - 1.0])[None, :, None]
        self.amplitude = reach * rng.dirichlet(np.ones(3), size=(agents, 2))
        self.omega = 2 * np.pi * rng.uniform(0.02, 0.10, size=(agents, 2, 3))
        self.phase = rng.uniform(0, 2 * np.pi, size=(agents, 2, 3))

    def at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(xy agents x 2 in m, heading rad) at `t_s`."""
        angle = self.omega * t_s + self.phase
        xy = self.centre + (self.amplitude * np.sin(angle)).sum(axis=2)
        velocity = (self.amplitude * self.omega * np.cos(angle)).sum(axis=2)
        return xy, np.arctan2(velocity[:, 1], velocity[:, 0])


def contacts(xy: np.ndarray, touching: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray]:
    """Pairs of chairs of one court that came within CONTACT_M since the last call, and who touches now."""
    padded = np.full((touching.shape[0] * COURT_AGENTS, 2), np.nan)
    padded[:len(xy)] = xy
    courts = padded.reshape(-1, COURT_AGENTS, 2)
    distance = np.linalg.norm(courts[:, :, None, :] - courts[:, None, :, :], axis=3)
    now = np.triu(distance < CONTACT_M, k=1)  # NaN (an empty seat of the last court) compares False
    court, a, b = np.nonzero(now & ~touching)
    return [(int(c * COURT_AGENTS + i), int(c * COURT_AGENTS + j)) for c, i, j in zip(court, a, b)], now


def rssi(truth: np.ndarray, beacons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """RSSI (dBm) of each chair's two goal beacons: log-distance path loss plus shadowing and fading."""
    horizontal = np.linalg.norm(beacons - truth[:, None, :], axis=2)
    slant = np.sqrt(horizontal**2 + (BEACON_HEIGHT_M - RECEIVER_HEIGHT_M) ** 2)
    return np.round(TX_POWER_DBM - 10 * PATH_LOSS_EXPONENT * np.log10(slant) + rng.normal(0, RSSI_SD_DB, slant.shape))

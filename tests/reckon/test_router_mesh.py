"""The venue router of deploy/zenoh/ on loopback: TLS, passwords, access control, two hubs sharded by venue.

A Python Zenoh session in router mode runs the generated router config (deploy/make-venue-access.py
over deploy/zenoh/router.json5) with certificates from deploy/make-certs.sh; hubs and edges are
clients with the generated configs, all loaded through `reckon.transport.bus.zenoh_config_from_file`. Only
the endpoints and the file paths are rewritten for the test. Denials are proved without waiting
on time: the denied messages go out first, an allowed one after them on the same link, and once the
allowed one has arrived (or a flush barrier has come back) the denied ones would have too.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import threading
from pathlib import Path

import json5
import numpy as np
import pytest

from protocol import bus as wire
from protocol import keys, messages
from protocol.session import load_toml
from protocol.session_log import LogMessages
from reckon.transport.bus import Alive, BusError, Publisher, Subscription, flush, open_session, wait_for_peers, zenoh_config_from_file
from reckon.processes.hub import run_hub
from support.venue import agent_table, sensor_table, write_venue

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
WAIT_S = 30.0  # upper bound for a ready signal; never reached when things work

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="deploy/make-certs.sh needs openssl")


def load_generator():
    spec = importlib.util.spec_from_file_location("make_venue_access", DEPLOY / "make-venue-access.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def rewrite(source: Path, target: Path, tls_dir: Path, users: Path | None = None,
            login: tuple[str, str] | None = None, certificate: str = "router") -> Path:
    """Copy a generated config with /etc/reckon paths pointed into the test's folder.

    `certificate`: the router's certificate name, instead of the config's router.pem/router.key.
    """
    document = json5.loads(source.read_text())
    tls = document["transport"]["link"]["tls"]
    for key, value in tls.items():
        if isinstance(value, str) and value.startswith("/etc/reckon/tls/"):
            tls[key] = str(tls_dir / Path(value).name.replace("router.", f"{certificate}."))
    if users is not None:
        document["transport"]["auth"]["usrpwd"]["dictionary_file"] = str(users)
    if login is not None:  # a router's own login to the router it dials (deploy/README.md, mesh)
        document["transport"]["auth"]["usrpwd"].update(user=login[0], password=login[1])
    target.write_text(json.dumps(document))
    return target


def make_ca(root: Path) -> Path:
    tls = root / "tls"
    subprocess.run([str(DEPLOY / "make-certs.sh"), str(tls), "ca"], check=True, capture_output=True)
    return tls


class Venues:
    """One router for the venues given, on a free port: its certificate, generated access files, config.

    `endpoint`: a free tcp endpoint (the router listens there, with tls/); `name`: the router's certificate name; `access_args`: more make-venue-access.py options;
    `dial`: (router, user name) to connect to another router of a mesh with that router's password.
    """

    def __init__(self, root: Path, venues: dict[str, list[str]], endpoint: str, tls: Path | None = None,
                 name: str = "router", access_args: tuple[str, ...] = (), dial: tuple["Venues", str] | None = None):
        self.root, self.venues = root, venues
        self.tls = tls or make_ca(root)
        subprocess.run([str(DEPLOY / "make-certs.sh"), str(self.tls), "server", name, "127.0.0.1"], check=True,
                       capture_output=True)
        self.access = root / f"access-{name}"
        specs = [f"{venue}={','.join(agents)}" for venue, agents in venues.items()]
        load_generator().main([arg for spec in specs for arg in ("--venue", spec)] + list(access_args)
                              + ["-o", str(self.access)])
        self.endpoint = endpoint.replace("tcp/", "tls/")
        login = None if dial is None else (dial[1], load_generator().read_users(dial[0].access / "users.txt")[dial[1]])
        router_file = rewrite(self.access / "router.json5", root / f"{name}.json5", self.tls,
                              users=self.access / "users.txt", login=login, certificate=name)
        self.router_config = zenoh_config_from_file(router_file, listen=[self.endpoint],
                                                    connect=[] if dial is None else [dial[0].endpoint])
        self.name = name

    def client(self, venue: str, name: str, password: str | None = None, user: str | None = None):
        """Config of `name` (`hub` or `edge-<agent>`) of `venue`, optionally with another login."""
        path = rewrite(self.access / venue / f"{name}.json5", self.root / f"{self.name}-{venue}-{name}.json5", self.tls)
        if password is not None or user is not None:
            document = json.loads(path.read_text())
            login = document["transport"]["auth"]["usrpwd"]
            login.update(password=password or login["password"], user=user or login["user"])
            # fail at once instead of re-dialling for ever (what a deployed edge does)
            document["connect"].update(timeout_ms=0, exit_on_failure=True)
            path.write_text(json.dumps(document))
        return zenoh_config_from_file(path, connect=[self.endpoint])


def session_toml(path: Path, venue: str, agents: list[str]) -> Path:
    chairs = [agent_table(agent, wheel_diameter_m=0.61, sensors=[sensor_table(f"{agent}-seat", "seat", rate_hz=100.0)])
              for agent in agents]
    return write_venue(path, venue, agents=chairs, court_length_m=28.0, court_width_m=15.0)


def batch(agent: str, sequence: int = 0):
    times = np.arange(3, dtype=np.int64) * 10_000_000 + 1_700_000_000_000_000_000
    return messages.imu_batch(agent, f"{agent}-seat", sequence, times, np.zeros((3, 3)), np.zeros((3, 3)), None)


def clock_sample(agent: str, sequence: int):
    return messages.new("ClockSample", timestamp_ns=sequence + 1, agent_id=agent, sensor_id=f"{agent}-seat",
                        received_ns=1_700_000_000_000_000_000 + sequence)


def correction(agent: str, dx_m: float):
    return messages.new("Correction", timestamp_ns=1, agent_id=agent, dx_m=dx_m)


def test_wrong_password_or_unknown_user_cannot_open_a_session(free_endpoint, tmp_path):
    venues = Venues(tmp_path, {"court1": ["chair1"]}, free_endpoint())
    with open_session(venues.router_config):
        with open_session(venues.client("court1", "edge-chair1")):  # the right password opens
            pass
        with pytest.raises(BusError, match="cannot open zenoh session"):
            with open_session(venues.client("court1", "edge-chair1", password="not-the-password")):
                pass
        with pytest.raises(BusError, match="cannot open zenoh session"):
            with open_session(venues.client("court1", "edge-chair1", user="edge.court1.chair9")):
                pass


def test_an_edge_publishes_only_under_its_own_agent_and_never_the_hubs_outputs(free_endpoint, tmp_path):
    venue = "court1"
    venues = Venues(tmp_path, {venue: ["chair1", "chair2"]}, free_endpoint())
    with open_session(venues.router_config), \
            open_session(venues.client(venue, "hub")) as hub_bus, \
            Subscription(hub_bus, f"reckon/{venue}/**") as observed, \
            Alive(hub_bus, venue, wire.Role.RECORDER, "observer"), \
            open_session(venues.client(venue, "edge-chair1")) as edge_bus, \
            Publisher(edge_bus) as edge:
        wait_for_peers(edge_bus, wire.alive_selector(venue, wire.Role.RECORDER), 1, WAIT_S)
        denied = [keys.imu(venue, "chair2", "chair2-seat"), keys.correction(venue, "chair1"),
                  keys.pose(venue, "chair1", "live"), keys.pose(venue, "chair1", "refined"), keys.identity(venue, "chair1")]
        for key in denied:
            edge.publish(key, batch("chair1"))
        allowed = [keys.imu(venue, "chair1", "chair1-seat"), keys.status(venue, "chair1", "chair1-seat"),
                   keys.pose(venue, "chair1", "edge")]
        for key in allowed:
            edge.publish(key, batch("chair1"))
        assert flush(edge_bus, wire.alive_selector(venue, wire.Role.RECORDER), WAIT_S) == \
            [wire.alive(venue, wire.Role.RECORDER, "observer")]
        # a denied message that got through would come before the allowed ones it preceded
        assert [observed.get(timeout=WAIT_S).key for _ in allowed] == allowed


def test_only_the_hub_reaches_an_edges_corrections_and_an_edge_hears_only_its_own(free_endpoint, tmp_path):
    venue = "court1"
    venues = Venues(tmp_path, {venue: ["chair1", "chair2"]}, free_endpoint())
    with open_session(venues.router_config), \
            open_session(venues.client(venue, "edge-chair2")) as edge_bus, \
            Subscription(edge_bus, [keys.correction(venue, "chair1"), keys.correction(venue, "chair2")]) as heard, \
            Alive(edge_bus, venue, wire.Role.EDGE, "chair2"), \
            open_session(venues.client(venue, "hub")) as hub_bus, \
            Publisher(hub_bus) as hub, \
            open_session(venues.client(venue, "edge-chair1")) as other_bus, \
            Publisher(other_bus) as other_edge:
        for bus in (hub_bus, other_bus):  # the token follows the subscriptions on the edge's link
            wait_for_peers(bus, wire.alive(venue, wire.Role.EDGE, "chair2"), 1, WAIT_S)
        other_edge.publish(keys.correction(venue, "chair2"), correction("chair2", 66.0))  # denied: not the hub
        # once the barrier is back, that put has reached chair2's handlers, had it got through
        assert flush(other_bus, wire.alive(venue, wire.Role.EDGE, "chair2"), WAIT_S) == \
            [wire.alive(venue, wire.Role.EDGE, "chair2")]
        hub.publish(keys.correction(venue, "chair1"), correction("chair1", 1.0))  # chair2 may not subscribe to it
        hub.publish(keys.correction(venue, "chair2"), correction("chair2", 2.0))
        first = heard.get(timeout=WAIT_S)
        assert (first.key, first.decode().dx_m) == (keys.correction(venue, "chair2"), 2.0)


def run_two_hubs(tmp_path: Path, hub_router: dict[str, Venues], edge_router: dict[str, Venues]) -> None:
    """A real `run_hub` per venue on its router, an edge per venue on its router; each hub's recording
    holds its own venue's batches, all of them (2 in court1, 3 in court2), and nothing else."""
    stop = threading.Event()
    hubs = {}
    for venue, router in hub_router.items():
        ready = threading.Event()
        session = load_toml(session_toml(tmp_path / f"{venue}.toml", venue, ["chair1"]))
        output = tmp_path / f"hub-{venue}.mcap"
        thread = threading.Thread(target=run_hub, args=(router.client(venue, "hub"), session, stop),
                                  kwargs={"output": output, "ready": ready}, daemon=True)
        thread.start()
        assert ready.wait(WAIT_S)
        hubs[venue] = (thread, output)
    counts = {"court1": 2, "court2": 3}
    for venue, router in edge_router.items():
        with open_session(router.client(venue, "edge-chair1")) as bus, Publisher(bus) as edge, \
                Alive(bus, venue, wire.Role.EDGE, "chair1"):
            wait_for_peers(bus, wire.alive_selector(venue, wire.Role.HUB), 1, WAIT_S)
            for sequence in range(counts[venue]):  # the clock samples: an input of every hub (raw IMU is asked for)
                edge.publish(keys.clock(venue, "chair1", "chair1-seat"), clock_sample("chair1", sequence))
            assert len(flush(bus, wire.alive_selector(venue, wire.Role.HUB), WAIT_S)) == 1
    stop.set()
    for thread, _ in hubs.values():
        thread.join(WAIT_S)
        assert not thread.is_alive()
    for venue, (_, output) in hubs.items():
        log = LogMessages(output, wanted=lambda topic, name: name == "ClockSample")
        topics = [(topic, message.timestamp_ns) for _, topic, message in log]
        assert topics == [(f"reckon/{venue}/chair1/clock/chair1-seat", sequence + 1) for sequence in range(counts[venue])]


def test_two_hubs_of_two_venues_through_one_router_each_get_only_their_venue(free_endpoint, tmp_path):
    venues = Venues(tmp_path, {"court1": ["chair1"], "court2": ["chair1"]}, free_endpoint())
    with open_session(venues.router_config):
        run_two_hubs(tmp_path, {"court1": venues, "court2": venues}, {"court1": venues, "court2": venues})


def test_two_routers_in_a_mesh_carry_each_venue_to_its_hub_across_them(free_endpoint, tmp_path):
    """Router b dials router a; each hub is on one router, each venue's edge on the other one."""
    both = {"court1": ["chair1"], "court2": ["chair1"]}
    tls = make_ca(tmp_path)
    a = Venues(tmp_path, both, free_endpoint(), tls, name="router-a", access_args=("--peer-router", "router.b"))
    b = Venues(tmp_path, both, free_endpoint(), tls, name="router-b", access_args=("--dialed-router", "router-a"),
               dial=(a, "router.b"))
    with open_session(a.router_config), open_session(b.router_config):
        run_two_hubs(tmp_path, {"court1": a, "court2": b}, {"court1": b, "court2": a})

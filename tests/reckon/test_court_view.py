"""The hub's live court view (reckon/web/court_view.py, the page in reckon/web/static/).

Unit: the fixed-size state (bounded rings, coalescing, truth error, ellipses) and the hub-side
hand-over that drops instead of blocking. End to end: a real `run_hub` with the view on loopback,
a scene published over real Zenoh (three chairs' edge poses, truth, a beacon pass, an operator's
fix, a QR scan, a DeviceStatus), the page in headless Debian Chromium: the agents appear and move,
the corrections show up on the court and in the list, status and the error against truth show.
The browser part is skipped when Debian's chromium is not installed (never downloads a browser)."""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ConfigError
from reckon.transport.bus import Publisher, flush, open_session, wait_for_peers, zenoh_config
from reckon.web.court_view import CourtView, parse_view_address
from reckon.web.court_state import POSE_HISTORY, TRUTH_HISTORY, ViewState, ellipse
from reckon.processes.hub import run_hub
from support.browser import CHROMIUM
from support.court import CHAIRS, STEP_NS, T0_NS, chair_xy, pose, session
from support.venue import write_venue

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]
WAIT_S = 30.0
SCREENSHOT = Path(__file__).resolve().parents[2] / "docs" / "img" / "court-view.png"
TRUTH_OFFSET_M = (0.3, 0.0)  # truth = edge pose + this: the error against truth is 0.30 m exactly
STATUS = messages.new("DeviceStatus", timestamp_ns=T0_NS, agent_id="c1", sensor_id="c1-seat", connected=True,
                      battery_pct=87.0, last_sample_age_s=0.02, samples=1000)


def correction(agent: str, sequence: int, kind=messages.CorrectionKind.BEACON):
    return messages.new("Correction", timestamp_ns=T0_NS + sequence, agent_id=agent, kind=kind, dx_m=0.5, dy_m=0.0,
                        source_id="goal-a", sequence=sequence)


# -- the state -----------------------------------------------------------------------------------


def test_corrections_ring_is_bounded_and_keeps_the_newest():
    state = ViewState(session(), ring=8)
    state.apply(pose("c1", T0_NS, 2.0, 7.0), 0)
    for sequence in range(1, 101):
        state.apply(correction("c1", sequence), sequence)
    snapshot = state.snapshot(200)
    assert [event["sequence"] for event in snapshot["events"]] == list(range(93, 101))
    assert snapshot["event_count"] == 100 and snapshot["agents"]["c1"]["corrections"] == {"beacon": 100}
    # placed where the agent was measured to be: its pose at that time plus the shift
    assert (snapshot["events"][-1]["x"], snapshot["events"][-1]["y"]) == (2.5, 7.0)


def test_histories_stay_bounded_and_unknown_agents_do_not_grow_the_state():
    state = ViewState(session())
    for i in range(10 * TRUTH_HISTORY):
        t = T0_NS + i * STEP_NS
        state.apply(messages.new("TruthPose", timestamp_ns=t, agent_id="c1", x_m=0.01 * i, y_m=1.0), t)
        state.apply(pose("c1", t, 0.01 * i, 1.0), t)
        state.apply(pose(f"ghost{i}", t, 0.0, 0.0), t)
    agent = state.agents["c1"]
    assert len(agent.truth_history) == TRUTH_HISTORY and len(agent.pose_history) == POSE_HISTORY
    assert set(state.agents) == set(CHAIRS) and state.unknown_agents == 10 * TRUTH_HISTORY
    assert len(json.dumps(state.snapshot(0))) < 4000


def test_coalescing_many_poses_give_one_snapshot_with_the_newest():
    state = ViewState(session())
    for i in range(1000):
        state.apply(pose("c2", T0_NS + i * STEP_NS, 0.01 * i, 3.0), i)
    live = state.snapshot(0)["agents"]["c2"]["live"]
    assert (live["x"], live["t_ns"]) == (9.99, T0_NS + 999 * STEP_NS)


def test_error_against_truth_interpolates_at_the_pose_time_and_keeps_a_running_mean():
    state = ViewState(session())
    for i in range(3):  # truth moves 1 m per step along x
        state.apply(messages.new("TruthPose", timestamp_ns=T0_NS + i * STEP_NS, agent_id="c3", x_m=float(i), y_m=0.0), 0)
    state.apply(pose("c3", T0_NS + STEP_NS // 2, 0.5, 0.4), 0)  # truth (0.5, 0) there: 0.4 m off
    state.score()
    state.score()  # the same pose is scored once
    state.apply(pose("c3", T0_NS + 2 * STEP_NS, 2.0, 0.2), 0)
    state.score()
    agent = state.snapshot(0)["agents"]["c3"]
    assert agent["error_m"] == pytest.approx(0.2) and agent["mean_error_m"] == pytest.approx(0.3)
    assert agent["scored"] == 2
    state.apply(pose("c3", T0_NS + 2 * STEP_NS + 10**9, 9.0, 9.0), 0)  # a second past the newest truth: no error
    state.score()
    assert state.snapshot(0)["agents"]["c3"]["scored"] == 2


def test_hub_pose_wins_over_the_edge_pose_and_status_ages():
    state = ViewState(session())
    state.apply(pose("c1", T0_NS, 1.0, 1.0), 0, is_input=True)
    assert state.snapshot(0)["agents"]["c1"]["live"]["from_edge"] is True
    state.apply(pose("c1", T0_NS, 1.5, 1.0), 0)
    state.apply(pose("c1", T0_NS + STEP_NS, 9.0, 9.0), 0, is_input=True)
    state.apply(STATUS, 10**9)
    agent = state.snapshot(3 * 10**9)["agents"]["c1"]
    assert agent["live"]["x"] == 1.5 and agent["input_age_s"] == 3.0
    assert agent["status"]["c1-seat"]["battery_pct"] == 87.0 and agent["status"]["c1-seat"]["age_s"] == 2.0


def test_values_json_cannot_carry_are_left_out_and_counted():
    state = ViewState(session())
    state.apply(pose("c1", T0_NS, 1.0, 2.0), 0)
    state.apply(pose("c1", T0_NS + STEP_NS, math.nan, 2.0), 0)
    state.apply(messages.new("TruthPose", timestamp_ns=T0_NS, agent_id="c1", x_m=math.inf, y_m=0.0), 0)
    state.apply(messages.new("Correction", timestamp_ns=T0_NS, agent_id="c1", dx_m=math.nan, dy_m=0.0, sequence=1), 0)
    state.apply(messages.new("DeviceStatus", agent_id="c1", sensor_id="s", battery_pct=math.nan), 0)
    snapshot = state.snapshot(0)
    text = json.dumps(snapshot, allow_nan=False)  # raises on NaN: the page's JSON.parse would too
    assert snapshot["agents"]["c1"]["live"]["x"] == 1.0 and snapshot["not_finite"] == 2
    assert snapshot["events"][0]["x"] is None and snapshot["agents"]["c1"]["status"]["s"]["battery_pct"] is None
    assert "NaN" not in text


def test_ellipse_matches_the_covariance_eigenvalues():
    covariance = np.array([[0.5, 0.2], [0.2, 0.3]])
    values, vectors = np.linalg.eigh(covariance)
    major, minor, angle = ellipse([0.5, 0.2, 0.0, 0.2, 0.3, 0.0, 0.0, 0.0, 0.01])
    assert major == pytest.approx(math.sqrt(5.991 * values[1])) and minor == pytest.approx(math.sqrt(5.991 * values[0]))
    assert abs(math.cos(angle) * vectors[0, 1] + math.sin(angle) * vectors[1, 1]) == pytest.approx(1.0)
    assert ellipse([]) is None and ellipse([1.0, 2.0, 2.0, 1.0]) is None  # not positive definite


def test_handover_drops_the_oldest_instead_of_blocking_the_hub():
    with CourtView(session(), "127.0.0.1", 0, ring=16) as view:
        view.server.close()  # stop the server's ticks: the view now never drains (a stalled browser side)
        view._thread.join(WAIT_S)
        for i in range(100):
            view.on_output(pose("c1", T0_NS + i, float(i), 0.0))
        assert view.dropped == 84
        view.drain()
        assert view.state.snapshot(0)["agents"]["c1"]["live"]["x"] == 99.0 and view.taken == 16


def test_view_address_is_checked():
    assert parse_view_address("127.0.0.1:8080") == ("127.0.0.1", 8080)
    assert parse_view_address("[::1]:0") == ("::1", 0)
    for bad in ("8080", "host:", "host:99999", ":80"):
        with pytest.raises(ConfigError, match="--view"):
            parse_view_address(bad)


# -- end to end in Chromium --------------------------------------------------------------------


def publish_steps(publisher: Publisher, steps: range) -> None:
    for step in steps:
        t = T0_NS + step * STEP_NS
        for agent in CHAIRS:
            x, y = chair_xy(agent, step)
            publisher.publish(keys.pose("court", agent, "edge"), pose(agent, t, x, y))
            publisher.publish(keys.truth("court", agent), messages.new(
                "TruthPose", timestamp_ns=t, agent_id=agent, x_m=x + TRUTH_OFFSET_M[0], y_m=y + TRUTH_OFFSET_M[1]))
        if step in (2, 5, 8):  # c1 hears the beacon strongly while passing it: a pass at 0.04-0.16 s
            publisher.publish(keys.beacon("court", "c1", "c1-seat"), messages.new(
                "BeaconSighting", timestamp_ns=t, agent_id="c1", sensor_id="c1-seat", beacon_id="goal-a", rssi_dbm=-60.0))
        if step == 60:  # an operator's fix of c2, half a metre ahead of its estimate
            x, y = chair_xy("c2", step)
            publisher.publish(keys.fix("court", "c2"), messages.new(
                "PositionFix", timestamp_ns=t, agent_id="c2", kind=messages.CorrectionKind.MANUAL, x_m=x + 0.5, y_m=y,
                covariance=[0.25, 0.0, 0.0, 0.25], source_id="operator"))
        if step == 70:
            publisher.publish(keys.scan("court", "c3"), messages.new(
                "StandScan", timestamp_ns=t, agent_id="c3", sensor_id="c3-seat", stand_id="bench", x_m=14.0, y_m=0.5,
                accepted=True))


def agent_xy(page, agent: str) -> tuple[float, float]:
    group = page.locator(f'g.agent[data-agent="{agent}"]')
    return float(group.get_attribute("data-x")), float(group.get_attribute("data-y"))


def test_page_shows_agents_moving_corrections_status_and_truth_error(browser_module, free_endpoint, tmp_path: Path):
    endpoint = free_endpoint()
    stop, ready = threading.Event(), threading.Event()
    results: dict = {}
    with CourtView(session(), "127.0.0.1", 0) as view:
        hub = threading.Thread(target=lambda: results.update(summary=run_hub(
            zenoh_config(listen=[endpoint]), session(), stop, ready=ready, on_input=view.on_input,
            on_output=view.on_output, on_bus=view.attach)), daemon=True)
        hub.start()
        assert ready.wait(WAIT_S)
        with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as publisher, \
                browser_module.sync_playwright() as playwright:
            wait_for_peers(bus, wire.alive_selector("court", wire.Role.HUB), 1, WAIT_S)
            browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 640})
                page.goto(view.url)
                page.wait_for_function("document.body.dataset.state === 'connected'")
                # first half second: every chair appears, 0.30 m from its truth
                publish_steps(publisher, range(25))
                publisher.publish(keys.status("court", "c1", "c1-seat"), STATUS)
                assert flush(bus, wire.alive_selector("court", wire.Role.HUB), WAIT_S)
                page.wait_for_function("""(x) => { const s = window.courtView.state;
                    return s && s.agents.c3.live && Math.abs(s.agents.c3.live.x - x) < 1e-9
                        && Object.keys(s.agents.c1.status).length === 1; }""", arg=chair_xy("c3", 24)[0])
                before = {agent: agent_xy(page, agent) for agent in CHAIRS}
                for agent in CHAIRS:
                    row = page.locator(f'#agents tr[data-agent="{agent}"]')
                    assert row.locator(".error").text_content() == "0.30"
                    assert row.locator(".mean").text_content() == "0.30"
                assert "battery 87 %" in page.locator('#agents tr[data-agent="c1"] .status').text_content()
                assert "last input" in page.locator('#agents tr[data-agent="c2"] .status').text_content()
                # then two more seconds: the beacon pass ends, the fix and the scan come in
                publish_steps(publisher, range(25, 125))
                assert flush(bus, wire.alive_selector("court", wire.Role.HUB), WAIT_S)
                page.wait_for_function("""(x) => { const s = window.courtView.state;
                    const kinds = new Set(s.events.map((e) => e.kind));
                    return Math.abs(s.agents.c3.live.x - x) < 1e-9 && kinds.has('beacon') && kinds.has('manual')
                        && kinds.has('qr'); }""", arg=chair_xy("c3", 124)[0])
                after = {agent: agent_xy(page, agent) for agent in CHAIRS}
                listed = page.locator("#events li").evaluate_all("items => items.map((i) => i.dataset.kind)")
                markers = page.locator("#layer-markers circle").count()
                corrections = page.locator('#agents tr[data-agent="c1"] .corrections').text_content()
                page.screenshot(path=str(tmp_path / "court-view.png"))
                if os.environ.get("RECKON_UPDATE_SCREENSHOTS"):  # docs/img's copy, refreshed on request
                    shutil.copyfile(tmp_path / "court-view.png", SCREENSHOT)
            finally:
                browser.close()
                stop.set()
                hub.join(WAIT_S)
    for agent in CHAIRS:  # moved with the scene (c1 and c2 also by their corrections)
        expected = np.subtract(chair_xy(agent, 124), chair_xy(agent, 24))
        moved = np.subtract(after[agent], before[agent])
        assert np.linalg.norm(moved - expected) < 0.8, (agent, moved, expected)
    assert before["c3"] == pytest.approx(chair_xy("c3", 24)) and after["c3"] == pytest.approx(chair_xy("c3", 124))
    assert sorted(set(listed)) == ["beacon", "manual", "qr"] and markers >= 3
    assert corrections == "beacon 1"
    assert results["summary"].inputs >= 125 * 3 + 1
    assert (tmp_path / "court-view.png").stat().st_size > 10_000


def test_hub_command_refuses_a_bad_or_taken_view_address(free_endpoint, tmp_path: Path, capsys):
    from reckon.cli import main

    venue = write_venue(tmp_path / "court.toml", "court", agents=[{"id": "c1"}])
    assert main(["hub", "--venue", str(venue), "--listen", free_endpoint(), "--view", "8080"]) == 2
    assert "--view '8080': expected HOST:PORT" in capsys.readouterr().err
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["hub", "--venue", str(venue), "--listen", free_endpoint(), "--view", f"127.0.0.1:{port}"]) == 2
    assert f"--view 127.0.0.1:{port}: cannot listen" in capsys.readouterr().err

"""A person with a phone, end to end: the phone page in headless Chromium scans the entrance stand
(a fake camera showing its code) and walks (synthetic DeviceMotion: a 1.8 Hz step bounce) ->
PhoneSource -> `run_edge` (our dead reckoning) -> Zenoh on loopback -> `run_hub` (map matching on
the venue's corridor) -> `pose/live`, read back by a separate Zenoh subscriber.
Skipped when Debian's chromium is not installed (never downloads a browser)."""

from __future__ import annotations

import math
import threading
from pathlib import Path

from protocol import keys
from protocol.session import load_toml
from reckon.transport.bus import Subscription, open_session, zenoh_config
from reckon.processes.edge import run_edge
from reckon.processes.hub import run_hub
from edge.sources.phone.server import PhoneSource
from support.browser import CHROMIUM
from support.phone import ARGS, FRAMES_PER_CODE, code_frame, entrance_code, make_venue, write_y4m

WAIT_S = 60.0
WALK_MS = 6000
CADENCE_HZ = 1.8
# The entrance stand (support/phone.py's hall) faces south (-y) at the top of a 4 m wide, 40 m long corridor.
CORRIDOR = [[[[1.3, -2.0], [5.3, -2.0], [5.3, 36.0], [1.3, 36.0]]]]
# A phone held flat walking: gravity on +z (W3C: a phone face up at rest reads +9.8), a vertical
# bounce of +-2.5 m/s^2 at the step rate, paced by the page's clock at about 100 Hz.
WALK = """async ([durationMs, cadenceHz]) => {
  const start = performance.now();
  let count = 0;
  while (performance.now() - start < durationMs) {
    const t = (performance.now() - start) / 1000;
    window.dispatchEvent(new DeviceMotionEvent("devicemotion", {
      accelerationIncludingGravity: {x: 0, y: 0.3 * Math.sin(2 * Math.PI * cadenceHz * t + 1),
                                     z: 9.81 + 2.5 * Math.sin(2 * Math.PI * cadenceHz * t)},
      rotationRate: {alpha: 0, beta: 0, gamma: 0}, interval: 10}));
    count++;
    await new Promise((resolve) => setTimeout(resolve, 10));
  }
  return count;
}"""


def test_scan_walk_and_see_the_position_on_the_hub(browser_module, free_endpoint, tmp_path: Path):
    venue_toml = make_venue(tmp_path, floor_plan=CORRIDOR)
    session = load_toml(venue_toml)
    endpoint = free_endpoint()
    stop_hub, stop_edge, hub_ready = threading.Event(), threading.Event(), threading.Event()
    results: dict = {}
    hub = threading.Thread(target=lambda: results.update(hub=run_hub(
        zenoh_config(listen=[endpoint]), session, stop_hub, output=tmp_path / "hub.mcap", ready=hub_ready)),
        daemon=True)
    hub.start()
    assert hub_ready.wait(WAIT_S)
    camera = write_y4m(tmp_path / "camera.y4m", [code_frame(entrance_code())] * FRAMES_PER_CODE)
    with open_session(zenoh_config(connect=[endpoint])) as bus, \
            Subscription(bus, keys.pose("hall", "walker", "live")) as live, \
            PhoneSource("phone://127.0.0.1:0", session, "walker", "phone", stop_edge,
                        venue_toml=venue_toml) as phone, browser_module.sync_playwright() as playwright:
        edge = threading.Thread(target=lambda: results.update(edge=run_edge(
            zenoh_config(connect=[endpoint]), session, "walker", phone, stop_edge, wait_for=1)), daemon=True)
        edge.start()
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                             args=ARGS + [f"--use-file-for-fake-video-capture={camera}"])
        try:
            page = browser.new_context(ignore_https_errors=True).new_page()
            page.goto(f"https://127.0.0.1:{phone.port}/")
            page.wait_for_function("document.body.dataset.state === 'connected'")
            page.click("#start")
            page.wait_for_function("document.body.dataset.lastScan !== undefined", timeout=WAIT_S * 1000)
            assert page.text_content("#scan").startswith("accepted: stand entrance")
            sent = page.evaluate(WALK, [WALK_MS, CADENCE_HZ])
            page.wait_for_function(f"Number(document.getElementById('sent').textContent) >= {sent}")
            poses = []
            while len(poses) < 6:  # the hub's map-matched poses, one per step
                item = live.get(timeout=WAIT_S)
                assert item is not None, "the live pose subscription closed"
                poses.append(item.decode())
        finally:
            browser.close()
            stop_edge.set()
            edge.join(WAIT_S)
            stop_hub.set()
            hub.join(WAIT_S)
    assert all(p.agent_id == "walker" and p.method == "reckon" and p.correction_sequence == 1 for p in poses)
    # walking south from the stand, one step (0.5-0.9 m) per pose, inside the corridor
    ys = [p.y_m for p in poses]
    assert ys[0] <= 33.55 + 0.5 and all(b < a for a, b in zip(ys, ys[1:])), ys
    steps = [a - b for a, b in zip(ys, ys[1:])]
    assert all(0.3 < s < 1.2 for s in steps), steps
    assert all(1.3 < p.x_m < 5.3 for p in poses)
    assert all(abs(math.degrees(p.heading_rad) + 90.0) < 15.0 for p in poses)
    edge_summary = results["edge"]
    assert edge_summary.poses >= len(poses)
    expected_steps = CADENCE_HZ * WALK_MS / 1000
    assert abs(edge_summary.poses - expected_steps) <= 3, (edge_summary.poses, expected_steps)

"""The phone page (edge/sources/phone/page/) end to end in headless Chromium: synthetic DeviceMotion events
and a fake camera showing stand codes (a genuine one, then a tampered one) go through the page,
the WebSocket and the server, and come out of the PhoneSource as ImuBatch and StandScan. The
camera's frames go to the edge, which reads the codes (`?scan=frames`, whatever the browser
has); a stand-in BarcodeDetector checks the page's other path, a code read on the phone.
Skipped when Debian's chromium is not installed (never downloads a browser)."""

from __future__ import annotations

import json
import queue
import threading
from pathlib import Path
from typing import Any

import numpy as np

from protocol.session import load_toml
from protocol.messages import STANDARD_GRAVITY_MS2
from edge.sources.phone.server import PhoneSource
from support.browser import CHROMIUM
from support.phone import (ARGS, FRAMES_PER_CODE, TIMEOUT_S, batch_times, code_frame, entrance_code, make_venue,
                           write_y4m)

SAMPLES = 60


def tampered(text: str) -> str:
    """The same code with its x moved by 1 cm: the integrity code no longer matches."""
    fields = text.split(":")
    fields[3] = str(int(fields[3]) + 1)
    return ":".join(fields)


def take_until(source: PhoneSource, done) -> list[Any]:
    out: list[Any] = []
    while not done(out):
        try:
            out.append(source.queue.get(timeout=TIMEOUT_S))
        except queue.Empty:
            raise AssertionError(f"the source gave {[m.DESCRIPTOR.name for m in out]} and then nothing") from None
    return out


DISPATCH = """async (count) => {
  const times = [];
  for (let i = 0; i < count; i++) {
    const event = new DeviceMotionEvent("devicemotion", {
      accelerationIncludingGravity: {x: 0.1 * i, y: 0.5, z: 9.8},
      rotationRate: {alpha: 30, beta: 10, gamma: 20}, interval: 10});
    window.dispatchEvent(event);
    times.push(performance.timeOrigin + event.timeStamp);
    await new Promise((resolve) => setTimeout(resolve, 2));  // distinct, increasing event times
  }
  return times;
}"""


def test_page_streams_motion_and_scans_codes(browser_module, tmp_path: Path):
    venue_toml = make_venue(tmp_path)
    genuine = entrance_code()
    camera = write_y4m(tmp_path / "camera.y4m", [code_frame(genuine)] * FRAMES_PER_CODE
                       + [code_frame(tampered(genuine))] * FRAMES_PER_CODE)
    stop = threading.Event()
    with PhoneSource("phone://127.0.0.1:0", load_toml(venue_toml), "walker", "phone", stop,
                     venue_toml=venue_toml) as source, browser_module.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                             args=ARGS + [f"--use-file-for-fake-video-capture={camera}"])
        try:
            page = browser.new_context(ignore_https_errors=True).new_page()
            page.goto(f"https://127.0.0.1:{source.port}/?scan=frames")
            page.wait_for_function("document.body.dataset.state === 'connected'")
            page.click("#start")
            page.wait_for_function("document.body.dataset.started === 'yes'")
            event_ms = page.evaluate(DISPATCH, SAMPLES)
            page.wait_for_function(f"document.getElementById('sent').textContent === '{SAMPLES}'")
            out = take_until(source, lambda got: sum(m.DESCRIPTOR.name == "ImuBatch" for m in got) >= 2
                             and {m.accepted for m in got if m.DESCRIPTOR.name == "StandScan"} == {True, False})
            page.wait_for_function("document.body.dataset.lastScan !== undefined")
            shown = page.text_content("#scan")
            scan_path, scanning = page.evaluate("document.body.dataset.scanPath"), page.text_content("#scanning")
        finally:
            browser.close()
        stop.set()
    batches = [m for m in out if m.DESCRIPTOR.name == "ImuBatch"]
    scans = [m for m in out if m.DESCRIPTOR.name == "StandScan"]
    # ordering and times: the page's event times (epoch ms) to whole microseconds, in ns
    assert batch_times(batches[:2]) == [round(t * 1000) * 1000 for t in event_ms[:50]]
    accel = np.concatenate([np.reshape(b.accel_g, (-1, 3)) for b in batches[:2]])
    np.testing.assert_allclose(accel[:, 0], 0.1 * np.arange(50) / STANDARD_GRAVITY_MS2, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(accel[:, 2], 9.8 / STANDARD_GRAVITY_MS2, rtol=1e-6)
    np.testing.assert_allclose(np.reshape(batches[0].gyro_dps, (-1, 3)), [[10.0, 20.0, 30.0]] * 25)  # x=beta, y=gamma, z=alpha
    assert list(batches[0].mag_gauss) == []  # a browser gives no magnetometer
    accepted = next(s for s in scans if s.accepted)
    refused = next(s for s in scans if not s.accepted)
    assert (accepted.stand_id, accepted.x_m, accepted.y_m, accepted.payload) == ("entrance", 3.3, 33.55, genuine)
    assert refused.payload == tampered(genuine) and refused.reason.startswith("integrity code does not match")
    assert shown.startswith("accepted: stand entrance") or shown.startswith("refused: integrity code")
    assert scan_path == "frames" and scanning.startswith("frames sent to the edge: ")


# A BarcodeDetector that reads the given text in every look, as Chrome on Android has one.
FAKE_DETECTOR = """(text) => {
  window.BarcodeDetector = class {
    static async getSupportedFormats() { return ["qr_code"]; }
    async detect() { return [{rawValue: text, format: "qr_code"}]; }
  };
}"""


def test_a_browser_that_reads_codes_itself_sends_the_text(browser_module, tmp_path: Path):
    venue_toml = make_venue(tmp_path)
    stop = threading.Event()
    with PhoneSource("phone://127.0.0.1:0", load_toml(venue_toml), "walker", "phone", stop,
                     venue_toml=venue_toml) as source, browser_module.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        try:
            context = browser.new_context(ignore_https_errors=True)
            context.add_init_script(script=f"({FAKE_DETECTOR})({json.dumps(entrance_code())})")
            page = context.new_page()
            page.goto(f"https://127.0.0.1:{source.port}/")
            page.wait_for_function("document.body.dataset.state === 'connected'")
            page.click("#start")
            out = take_until(source, lambda got: any(m.DESCRIPTOR.name == "StandScan" for m in got))
            page.wait_for_function("document.body.dataset.lastScan === 'accepted'")
            scan_path, scanning = page.evaluate("document.body.dataset.scanPath"), page.text_content("#scanning")
        finally:
            browser.close()
        stop.set()
    assert (scan_path, scanning) == ("detector", "read on this phone")
    assert [(m.accepted, m.stand_id, m.payload) for m in out] == [(True, "entrance", entrance_code())]

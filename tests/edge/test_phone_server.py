"""The phone server (edge/sources/phone/server.py) on 127.0.0.1: the Sensor Logger push with aiohttp's
client, the page's WebSocket with bad input, the certificate, and `--source SENSOR=phone://`.
The browser itself is in tests/edge/test_phone_browser.py."""

from __future__ import annotations

import asyncio
import json
import math
import threading
from pathlib import Path
from typing import Any

import aiohttp
import numpy as np
import pytest
from cryptography import x509

from protocol.errors import ConfigError
from protocol.session import load_toml
from edge.sources.registry import open_sources
from edge.sources.phone.server import PhoneSource, parse_phone_url
from edge.sources.phone.tls import ensure_certificate
from support.phone import T0_NS, batch_times, entrance_code, take, talk, unverified


def logger_body(start: int, count: int, accel=(0.0, 0.0, 9.80665), message_id: int = 1) -> str:
    payload = []
    for i in range(start, start + count):
        t = T0_NS + i * 10_000_000
        payload.append({"name": "accelerometer", "time": t, "values": dict(zip("xyz", accel))})
        payload.append({"name": "gyroscope", "time": t, "values": {"x": 0.5, "y": 0.0, "z": -0.25}})
        payload.append({"name": "magnetometer", "time": t, "values": {"x": 20.0, "y": -10.0, "z": 40.0}})
        payload.append({"name": "light", "time": t, "values": {"lux": 100}})
    return json.dumps({"messageId": message_id, "sessionId": "s1", "deviceId": "pixel", "payload": payload})


async def post_all(url: str, bodies: list[str]) -> list[tuple[int, dict[str, Any]]]:
    async with aiohttp.ClientSession() as client:
        replies = []
        for body in bodies:
            async with client.post(url, data=body, ssl=unverified()) as response:
                replies.append((response.status, await response.json()))
        return replies


def test_sensor_logger_push_becomes_imu_batches_in_g_deg_s_gauss(phone: PhoneSource):
    url = f"https://127.0.0.1:{phone.port}/sensorlogger"
    replies = asyncio.run(post_all(url, [logger_body(0, 30), logger_body(30, 30, message_id=2), "not json",
                                         json.dumps({"payload": 3})]))
    assert [status for status, _ in replies] == [200, 200, 400, 400]
    assert replies[2][1]["reason"].startswith("not JSON")
    batches = take(phone, 2)  # 60 samples, 25 per batch; the rest is held until more come or the end
    assert [b.sequence for b in batches] == [0, 1]
    assert batch_times(batches) == [T0_NS + i * 10_000_000 for i in range(50)]
    accel, gyro, mag = (np.reshape(getattr(batches[0], f), (-1, 3)) for f in ("accel_g", "gyro_dps", "mag_gauss"))
    np.testing.assert_allclose(accel[0], [0.0, 0.0, 1.0], rtol=1e-6)
    np.testing.assert_allclose(gyro[0], np.degrees([0.5, 0.0, -0.25]), rtol=1e-6)
    np.testing.assert_allclose(mag[0], [0.2, -0.1, 0.4], rtol=1e-6)
    assert all(b.received_ns > T0_NS for b in batches)  # the host clock at arrival
    assert phone.counters.ignored_names == 60 and phone.counters.bad_messages == 2


def test_plain_http_push_and_acceleration_in_g_is_converted(phone: PhoneSource):
    url = f"http://127.0.0.1:{phone.http_port}/sensorlogger"
    replies = asyncio.run(post_all(url, [logger_body(0, 60, accel=(0.0, 0.6, 0.8))]))
    assert replies[0][0] == 200
    batches = take(phone, 2)
    np.testing.assert_allclose(np.reshape(batches[0].accel_g, (-1, 3))[0], [0.0, 0.6, 0.8], rtol=1e-6)
    assert phone.counters.converted_g >= 50


def motion(start: int, count: int, accel=(0.0, 0.0, 9.81), skip_time_of: int | None = None) -> dict[str, Any]:
    rows = [[T0_NS / 1e6 + i * 10.0, *accel, 30.0, 10.0, 20.0, 10.0] for i in range(start, start + count)]
    if skip_time_of is not None:
        rows[1][0] = T0_NS / 1e6 + skip_time_of * 10.0
    return {"type": "motion", "samples": rows}


def test_websocket_bad_input_is_counted_and_the_good_kept(phone: PhoneSource):
    url = f"wss://127.0.0.1:{phone.port}/ws"
    bad_nan = motion(30, 1)
    bad_nan["samples"][0][1] = None
    sent = [motion(0, 30, skip_time_of=0), "{not json", {"type": "motion", "samples": [[1, 2]]}, bad_nan,
            motion(31, 30), {"type": "orientation", "samples": [[T0_NS / 1e6, 10.0, 20.0, 30.0, 0]]},
            {"type": "scan", "t": T0_NS / 1e6, "text": entrance_code()},
            {"type": "scan", "t": T0_NS / 1e6, "text": "https://example.com/menu"}]
    replies = asyncio.run(talk(url, sent))
    assert replies[1] == {"type": "problem", "text": replies[1]["text"]} and "not JSON" in replies[1]["text"]
    assert "sample 0 must be a list of 8 values" in replies[2]["text"]
    assert replies[6]["accepted"] is True and replies[6]["stand_id"] == "entrance"
    assert replies[7]["accepted"] is False and replies[7]["reason"].startswith("not a reckon stand code")
    out = take(phone, 4)  # two batches of 25, then the two scans
    names = [m.DESCRIPTOR.name for m in out]
    assert names == ["ImuBatch", "ImuBatch", "StandScan", "StandScan"]
    expected = [T0_NS + i * 10_000_000 for i in range(60) if i not in (1, 30)]  # 1: backwards, 30: NaN
    assert batch_times(out[:2]) == expected[:50]
    np.testing.assert_allclose(np.reshape(out[0].gyro_dps, (-1, 3))[0], [10.0, 20.0, 30.0])  # beta, gamma, alpha
    scan = out[2]
    assert (scan.accepted, scan.stand_id, scan.x_m, scan.y_m) == (True, "entrance", 3.3, 33.55)
    assert scan.timestamp_ns == T0_NS and scan.agent_id == "walker" and scan.sensor_id == "phone"
    counters = phone.counters
    assert (counters.backwards, counters.non_finite, counters.bad_messages, counters.orientation) == (1, 1, 2, 1)


def test_stop_flushes_held_samples_and_ends_the_iteration(venue_toml: Path):
    stop = threading.Event()
    source = PhoneSource("phone://127.0.0.1:0", load_toml(venue_toml), "walker", "phone", stop,
                         venue_toml=venue_toml)
    asyncio.run(talk(f"wss://127.0.0.1:{source.port}/ws", [motion(0, 30)]))
    stop.set()
    out = list(source)  # ends: the server stopped and flushed what it held
    assert batch_times(out) == [T0_NS + i * 10_000_000 for i in range(30)]


def test_certificate_is_made_once_and_names_the_host(tmp_path: Path):
    cert_path, key_path = ensure_certificate(tmp_path / "tls", "127.0.0.1")
    first = cert_path.read_bytes()
    assert ensure_certificate(tmp_path / "tls", "127.0.0.1") == (cert_path, key_path)
    assert cert_path.read_bytes() == first  # reused
    assert oct(key_path.stat().st_mode & 0o777) == "0o600"
    assert oct((tmp_path / "tls" / "ca-key.pem").stat().st_mode & 0o777) == "0o600"
    cert = x509.load_pem_x509_certificate(first)
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "localhost" in san.get_values_for_type(x509.DNSName)
    assert "127.0.0.1" in {str(a) for a in san.get_values_for_type(x509.IPAddress)}
    ca = x509.load_pem_x509_certificate((tmp_path / "tls" / "ca.pem").read_bytes())
    cert.verify_directly_issued_by(ca)
    # a new name: the server certificate is issued again by the same CA (phones keep trusting it)
    ensure_certificate(tmp_path / "tls", "reckon-hub.local")
    again = x509.load_pem_x509_certificate(cert_path.read_bytes())
    assert "reckon-hub.local" in again.extensions.get_extension_for_class(x509.SubjectAlternativeName).value.get_values_for_type(x509.DNSName)
    again.verify_directly_issued_by(ca)


def test_edge_source_url(venue_toml: Path):
    stop = threading.Event()
    session, source = open_sources(["phone=phone://127.0.0.1:0"], "walker", 1.0, stop, venue_toml)
    try:
        assert isinstance(source, PhoneSource) and source.port > 0
        assert source.tls_dir == venue_toml.parent / "phone-tls" and (source.tls_dir / "ca.pem").exists()
        assert session.venue.name == "hall"
    finally:
        source.close()
        assert list(source) == []  # ends once the server has stopped
    with pytest.raises(ConfigError, match="has no sensor 'seat'"):
        open_sources(["seat=phone://127.0.0.1:0"], "walker", 1.0, stop, venue_toml)
    with pytest.raises(ConfigError, match="a phone source goes alone"):
        open_sources(["phone=phone://127.0.0.1:0", "x=phone://127.0.0.1:0"], "walker", 1.0, stop, venue_toml)
    with pytest.raises(ConfigError, match="'x=serial:///dev/null': phone and serial sources cannot be mixed"):
        open_sources(["phone=phone://127.0.0.1:0", "x=serial:///dev/null"], "walker", 1.0, stop, venue_toml)
    with pytest.raises(ConfigError, match="--venue VENUE.toml is needed"):
        open_sources(["phone=phone://127.0.0.1:0"], "walker", 1.0, stop, None)
    for url, reason in (("phone://127.0.0.1", "no port"), ("phone://127.0.0.1:1?color=red", "unknown key 'color'"),
                        ("phone://127.0.0.1:1?http_port=x", "http_port 'x'")):
        with pytest.raises(ConfigError, match=reason):
            parse_phone_url(url)


def test_missing_stand_key_fails_at_start(venue_toml: Path):
    (venue_toml.parent / "hall.standkey").unlink()
    with pytest.raises(ConfigError, match="no stand key file there"):
        PhoneSource("phone://127.0.0.1:0", load_toml(venue_toml), "walker", "phone", threading.Event(),
                    venue_toml=venue_toml)


def test_websocket_rotation_in_rad_s_is_converted(phone: PhoneSource):
    rate_dps = 90.0  # turning about z; this browser reports the rate in rad/s
    count = 300
    rows = [[T0_NS / 1e6 + i * 10.0, 0.0, 0.0, 9.81, math.radians(rate_dps), 0.0, 0.0, 10.0] for i in range(count)]
    orientation = [[T0_NS / 1e6 + i * 10.0, (rate_dps * i * 0.01) % 360.0, 0.0, 0.0, 0] for i in range(count)]
    later = [[T0_NS / 1e6 + i * 10.0, 0.0, 0.0, 9.81, math.radians(rate_dps), 0.0, 0.0, 10.0]
             for i in range(count, count + 25)]
    replies = asyncio.run(talk(f"wss://127.0.0.1:{phone.port}/ws", [
        {"type": "motion", "samples": rows}, {"type": "orientation", "samples": orientation},
        {"type": "motion", "samples": later}]))
    assert "looks like rad/s" in replies[1]["problem"]
    batches = take(phone, count // 25 + 1)
    assert np.reshape(batches[0].gyro_dps, (-1, 3))[0, 2] == pytest.approx(math.radians(rate_dps), rel=1e-6)
    assert np.reshape(batches[-1].gyro_dps, (-1, 3))[0, 2] == pytest.approx(rate_dps, rel=1e-6)
    assert phone.counters.converted_rad_s == 25

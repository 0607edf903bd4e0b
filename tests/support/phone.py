"""The phone tests' hall (one stand, one walker with a phone), its stand key and code, and the
fake camera Chromium plays to the phone page (tests/edge/test_phone_*.py, test_pedestrian_live.py)."""

from __future__ import annotations

import io
import json
import queue
import ssl
from pathlib import Path
from typing import Any

import aiohttp
import numpy as np
import segno
from PIL import Image

from protocol.session import Stand
from protocol.stand_code import encode
from edge.sources.phone.stand_key import write_key
from support.venue import agent_table, sensor_table, write_venue

KEY = bytes(range(32))
ENTRANCE = Stand("entrance", 3.3, 33.55, heading_deg=-90.0)  # as in HALL
HALL: dict[str, Any] = {
    "stands": [{"id": "entrance", "x_m": 3.3, "y_m": 33.55, "heading_deg": -90.0}],
    "agents": [agent_table("walker", "pedestrian", sensors=[sensor_table("phone", "hand", rate_hz=100.0)])],
}
TIMEOUT_S = 20.0
T0_NS = 1_764_000_000_000_000_000  # the phones' first sample time in the tests

# Chromium's fake camera
FRAME_W, FRAME_H = 480, 360
FRAMES_PER_CODE = 10  # at 10 fps each code is in view for 1 s, several of the page's 250 ms looks
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--use-fake-device-for-media-stream", "--use-fake-ui-for-media-stream"]


def make_venue(folder: Path, **changes: Any) -> Path:
    """`folder/hall.toml` (HALL with `changes` to its [venue] keys) and the hall's stand key beside it."""
    path = write_venue(folder / "hall.toml", "hall", **{**HALL, **changes})
    write_key(folder / "hall.standkey", KEY)
    return path


def entrance_code() -> str:
    return encode(ENTRANCE, "hall", KEY)


def batch_times(batches: list[Any]) -> list[int]:
    return [b.timestamp_ns + offset for b in batches for offset in b.sample_offset_ns]


def code_frame(text: str) -> np.ndarray:
    """A grey camera frame with the code in the middle, 7 px per module (as a phone ~20 cm away)."""
    buffer = io.BytesIO()
    segno.make(text, error="q", mode="byte", micro=False).save(buffer, kind="png", scale=7, border=4)
    code = Image.open(buffer).convert("L")
    frame = Image.new("L", (FRAME_W, FRAME_H), 200)
    frame.paste(code, ((FRAME_W - code.width) // 2, (FRAME_H - code.height) // 2))
    return np.asarray(frame)


def write_y4m(path: Path, frames: list[np.ndarray]) -> Path:
    """Frames as a 4:2:0 YUV4MPEG2 file (grey: chroma 128), what Chromium's fake camera plays."""
    with path.open("wb") as file:
        file.write(f"YUV4MPEG2 W{FRAME_W} H{FRAME_H} F10:1 Ip A1:1 C420jpeg\n".encode("ascii"))
        chroma = bytes([128]) * (FRAME_W // 2 * FRAME_H // 2)
        for luma in frames:
            file.write(b"FRAME\n" + luma.astype(np.uint8).tobytes() + chroma + chroma)
    return path


def take(source: Any, count: int) -> list[Any]:
    """The next `count` messages out of a PhoneSource (fails after TIMEOUT_S: no sleeps)."""
    out = []
    for _ in range(count):
        try:
            out.append(source.queue.get(timeout=TIMEOUT_S))
        except queue.Empty:
            raise AssertionError(f"only {len(out)} of {count} messages came out of the source") from None
    return out


def unverified() -> ssl.SSLContext:
    return ssl._create_unverified_context()  # the test trusts its own fresh certificate


async def talk(url: str, sent: list[Any]) -> list[dict[str, Any]]:
    """Send each message on the page's WebSocket and collect one reply per message."""
    async with aiohttp.ClientSession() as client, client.ws_connect(url, ssl=unverified()) as socket:
        replies = []
        for message in sent:
            await socket.send_str(message if isinstance(message, str) else json.dumps(message))
            replies.append(await socket.receive_json(timeout=TIMEOUT_S))
        return replies

"""The phone page's camera frames (edge/decoders/phone/qr_frame.py): a stand code drawn with segno
and sent as a JPEG is read back; bad frames are refused with the value and the limit, counted,
and the stream goes on; the page's `frame` message over the server's WebSocket."""

from __future__ import annotations

import asyncio
import base64
import io
import json

import numpy as np
import pytest
import segno
from PIL import Image

from edge.decoders.phone.parse import PhoneInputError, parse_browser
from edge.decoders.phone.qr_frame import (MAX_FRAME_BYTES, MAX_FRAME_SIDE_PX, SAME_CODE_AGAIN_NS, FrameOutcome,
                                          QrFrameError, QrFrameReader, decode_frame)
from edge.sources.phone.server import PhoneSource
from support.phone import T0_NS, entrance_code, take, talk

WIDTH, HEIGHT = 480, 360
TEXT = "reckon stand code under test"


def frame_jpeg(text: str | None, width: int = WIDTH, height: int = HEIGHT, quality: int = 80) -> bytes:
    """A grey frame with the code in the middle at 6 px per module, as the page's JPEG."""
    frame = Image.new("L", (width, height), 190)
    if text is not None:
        buffer = io.BytesIO()
        segno.make(text, error="q", mode="byte", micro=False).save(buffer, kind="png", scale=6, border=4)
        code = Image.open(buffer).convert("L")
        frame.paste(code, ((width - code.width) // 2, (height - code.height) // 2))
    out = io.BytesIO()
    frame.save(out, "JPEG", quality=quality)
    return out.getvalue()


def frame_message(jpeg: bytes, t_ms: float = T0_NS / 1e6, width: int = WIDTH, height: int = HEIGHT) -> dict:
    return {"type": "frame", "t": t_ms, "width": width, "height": height, "jpeg": base64.b64encode(jpeg).decode()}


def test_a_code_in_a_jpeg_frame_is_read():
    assert decode_frame(frame_jpeg(TEXT), WIDTH, HEIGHT) == TEXT
    assert decode_frame(frame_jpeg(entrance_code(), 640, 480), 640, 480) == entrance_code()
    assert decode_frame(frame_jpeg(None), WIDTH, HEIGHT) is None


@pytest.mark.parametrize("jpeg, width, height, reason", [
    (b"", WIDTH, HEIGHT, "frame of 0 bytes does not start as a JPEG (got nothing, expected ffd8ff)"),
    (b"\x89PNG\r\n\x1a\n" + bytes(100), WIDTH, HEIGHT, "does not start as a JPEG (got 89504e"),
    (b"\xff\xd8\xff" + bytes(np.random.default_rng(7).integers(0, 256, 4000, dtype=np.uint8)), WIDTH, HEIGHT,
     "frame of 4003 bytes is not a readable JPEG"),
    (frame_jpeg(TEXT)[:3000], WIDTH, HEIGHT, "frame of 3000 bytes is not a readable JPEG"),
    (frame_jpeg(TEXT), 640, HEIGHT, "frame is 480 x 360 px, the message says 640 x 360"),
    (frame_jpeg(TEXT), MAX_FRAME_SIDE_PX + 1, HEIGHT, f"frame width {MAX_FRAME_SIDE_PX + 1} px is outside [21, 1024]"),
    (frame_jpeg(TEXT), WIDTH, 0, "frame height 0 px is outside [21, 1024]"),
    (b"\xff\xd8\xff" + bytes(MAX_FRAME_BYTES), WIDTH, HEIGHT, f"frame of {MAX_FRAME_BYTES + 3} bytes exceeds {MAX_FRAME_BYTES}"),
])
def test_a_bad_frame_is_refused_naming_the_value_and_limit(jpeg: bytes, width: int, height: int, reason: str):
    with pytest.raises(QrFrameError) as error:
        decode_frame(jpeg, width, height)
    assert reason in error.value.reason


def test_a_code_longer_than_a_scan_text_is_refused():
    with pytest.raises(QrFrameError, match="QR code of 1200 characters exceeds 1000"):
        decode_frame(frame_jpeg("x" * 1200, 1000, 1000), 1000, 1000)


def test_the_reader_counts_garbage_and_goes_on():
    reader = QrFrameReader()
    problems: list[str] = []
    code = frame_jpeg(TEXT)
    assert reader.feed(T0_NS, b"garbage", WIDTH, HEIGHT, problems) == (FrameOutcome.BAD, None)
    assert reader.counts.bad_frames == 1 and len(problems) == 1 and "7 bytes does not start as a JPEG" in problems[0]
    assert reader.feed(T0_NS + 1, code, WIDTH, HEIGHT, problems) == (FrameOutcome.CODE, TEXT)
    assert reader.feed(T0_NS + 2, code[:500], WIDTH, HEIGHT, problems) == (FrameOutcome.BAD, None)
    assert reader.feed(T0_NS + 3, frame_jpeg(None), WIDTH, HEIGHT, problems) == (FrameOutcome.NO_CODE, None)
    assert (reader.counts.frames, reader.counts.bad_frames, reader.counts.codes, reader.counts.no_code) == (4, 2, 1, 1)
    assert len(problems) == 2


def test_the_same_code_is_passed_on_again_only_after_five_seconds_of_phone_time():
    reader = QrFrameReader()
    code, other = frame_jpeg(TEXT), frame_jpeg("another code")
    outcomes = [reader.feed(T0_NS + offset_ns, jpeg, WIDTH, HEIGHT, [])[0] for offset_ns, jpeg in [
        (0, code), (1_000_000_000, code), (SAME_CODE_AGAIN_NS - 1, code), (SAME_CODE_AGAIN_NS, code),
        (SAME_CODE_AGAIN_NS + 1, other), (SAME_CODE_AGAIN_NS + 2, code)]]
    assert outcomes == [FrameOutcome.CODE, FrameOutcome.REPEAT, FrameOutcome.REPEAT, FrameOutcome.CODE,
                        FrameOutcome.CODE, FrameOutcome.CODE]
    assert (reader.counts.codes, reader.counts.repeats) == (4, 2)


def test_the_frame_message_envelope():
    jpeg = frame_jpeg(TEXT)
    assert parse_browser(json.dumps(frame_message(jpeg))) == ("frame", (T0_NS, jpeg, WIDTH, HEIGHT))
    for change, reason in [({"t": None}, "frame: \"t\" must be epoch milliseconds"),
                           ({"width": 480.5}, "\"width\" and \"height\" must be whole pixels"),
                           ({"height": True}, "\"width\" and \"height\" must be whole pixels"),
                           ({"jpeg": 12}, "\"jpeg\" must be base64 text, got int"),
                           ({"jpeg": "not base64!"}, "\"jpeg\" is not base64")]:
        with pytest.raises(PhoneInputError) as error:
            parse_browser(json.dumps({**frame_message(jpeg), **change}))
        assert reason in error.value.reason


def test_frames_over_the_websocket_scan_the_stand_and_a_bad_one_does_not_stop_the_stream(phone: PhoneSource):
    genuine = frame_jpeg(entrance_code())
    sent = [frame_message(b"\xff\xd8\xff not a jpeg"), frame_message(frame_jpeg(None)), frame_message(genuine),
            frame_message(genuine, t_ms=T0_NS / 1e6 + 250), {"type": "frame", "t": T0_NS / 1e6, "jpeg": 3},
            {"type": "scan", "t": T0_NS / 1e6 + 300, "text": "https://example.com/menu"}]
    replies = asyncio.run(talk(f"wss://127.0.0.1:{phone.port}/ws", sent))
    assert replies[0]["type"] == "frame_result" and replies[0]["frame"] == "bad"
    assert "is not a readable JPEG" in replies[0]["problem"]  # the first problem is told at once
    assert (replies[1]["type"], replies[1]["frame"]) == ("frame_result", "none")
    assert (replies[2]["type"], replies[2]["frame"], replies[2]["accepted"], replies[2]["stand_id"]) == \
        ("scan_result", "code", True, "entrance")
    assert (replies[3]["type"], replies[3]["frame"]) == ("frame_result", "repeat")
    assert replies[4]["type"] == "problem" and "\"width\" and \"height\" must be whole pixels" in replies[4]["text"]
    assert replies[5]["type"] == "scan_result" and replies[5]["accepted"] is False  # the text path is unchanged
    scans = take(phone, 2)
    assert [(s.accepted, s.stand_id, s.timestamp_ns) for s in scans] == [(True, "entrance", T0_NS),
                                                                         (False, "", T0_NS + 300_000_000)]
    assert scans[0].payload == entrance_code()
    assert (phone.counters.scans, phone.counters.bad_messages) == (2, 1)

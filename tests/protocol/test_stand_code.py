"""QR calibration stands: the code's text and integrity (protocol/stand_code.py), the key file
(edge/sources/phone/stand_key.py), printable codes and reading them back from images (reckon/tools/qr.py),
and `reckon qr make|read`."""

from __future__ import annotations

import argparse
import io
import math
import os
import stat
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image, ImageDraw, ImageFilter

from protocol.errors import ConfigError, InputError
from protocol.session import Session, Stand, Venue
from protocol.stand_code import StandCodeError, decode, encode, new_key, scan_message
from reckon.cli import qr as qr_command
from reckon.tools import qr
from edge.sources.phone.stand_key import load_key, write_key
from support.venue import agent_table, write_venue

KEY = bytes(range(32))
OTHER_KEY = bytes(range(1, 33))
ENTRANCE = Stand("entrance", 3.3, 33.55, floor=0, heading_deg=-90.0, tilt_deg=0.0)
LIFT = Stand("lift-3", -12.5, 4.0, floor=2, heading_deg=180.0, tilt_deg=10.0)
STANDS = (ENTRANCE, LIFT)


def hall(path: Path) -> Path:
    """The hall's venue file: STANDS (the entrance with the loader's defaults for floor and tilt), one walker."""
    return write_venue(path, "hall", agents=[agent_table("walker", "pedestrian")], stands=[
        {"id": "entrance", "x_m": 3.3, "y_m": 33.55, "heading_deg": -90.0},
        {"id": "lift-3", "x_m": -12.5, "y_m": 4.0, "floor": 2, "heading_deg": 180.0, "tilt_deg": 10.0}])


def reason(text: str, venue: str = "hall", key: bytes = KEY, stands: tuple[Stand, ...] = STANDS) -> str:
    with pytest.raises(StandCodeError) as caught:
        decode(text, venue, key, stands)
    return caught.value.reason


# ---------------------------------------------------------------------------------------------
# The code's text


ids = st.from_regex(r"[A-Za-z0-9_-]{1,64}", fullmatch=True)


@settings(max_examples=200, deadline=None)
@given(venue=ids, stand_id=ids, x_m=st.floats(-1e4, 1e4), y_m=st.floats(-1e4, 1e4), floor=st.integers(-20, 200),
       heading_deg=st.floats(-360, 360), tilt_deg=st.floats(-90, 90))
def test_round_trip_within_the_codes_resolution(venue, stand_id, x_m, y_m, floor, heading_deg, tilt_deg):
    stand = Stand(stand_id, x_m, y_m, floor, heading_deg, tilt_deg)
    text = encode(stand, venue, KEY)
    # Checked against the venue file too: the code's own rounding never reads as a stale print.
    back = decode(text, venue, KEY, stands=(stand,))
    assert back.id == stand_id and back.floor == floor
    for name in ("x_m", "y_m", "heading_deg", "tilt_deg"):
        assert abs(getattr(back, name) - getattr(stand, name)) <= 0.005 + 1e-9, name
    assert text.isascii() and len(text) <= 200


def test_text_layout_is_the_documented_one():
    text = encode(ENTRANCE, "hall", KEY)
    assert text.startswith("RKS1:hall:entrance:330:3355:0:-9000:0:") and len(text.rsplit(":", 1)[1]) == 11
    assert encode(ENTRANCE, "hall", KEY) == text  # deterministic: reprinting gives the same code


def test_one_changed_digit_breaks_the_integrity_code():
    text = encode(ENTRANCE, "hall", KEY)
    tampered = text.replace(":3355:", ":3365:")  # y moved 10 cm
    assert tampered != text
    assert reason(tampered).startswith("integrity code does not match")
    tag = text.rsplit(":", 1)[1]
    flipped = text[:-1] + ("A" if tag[-1] != "A" else "B")
    assert reason(flipped).startswith("integrity code does not match")


def test_another_venues_code_is_refused_by_name():
    assert reason(encode(ENTRANCE, "gym", KEY)) == "another venue's code: it is for venue 'gym', this is venue 'hall'"


def test_wrong_key_and_forged_code_are_refused():
    assert reason(encode(ENTRANCE, "hall", OTHER_KEY)).startswith("integrity code does not match")
    # A visitor's forgery: the right venue and a listed stand, a believable position, a valid
    # layout, made with a key of their own (or a guessed tag).
    forged = encode(Stand("entrance", 3.3, 20.0, heading_deg=-90.0), "hall", new_key())
    assert reason(forged).startswith("integrity code does not match")
    assert reason(forged.rsplit(":", 1)[0] + ":AAAAAAAAAAA").startswith("integrity code does not match")


def test_unknown_stand_and_stale_print_are_refused():
    removed = encode(Stand("stairs", 1.0, 2.0), "hall", KEY)
    assert reason(removed).startswith("stand 'stairs' is not listed in venue 'hall'")
    assert decode(removed, "hall", KEY) == Stand("stairs", 1.0, 2.0)  # no venue list given: not checked
    moved = encode(Stand("entrance", 3.3, 30.0, heading_deg=-90.0), "hall", KEY)  # printed before a move
    assert reason(moved) == ("stale print of stand 'entrance': the code says x 3.30 m, y 30.00 m where the venue "
                             "file has x 3.30 m, y 33.55 m; print its code again (reckon qr make)")
    turned = encode(Stand("lift-3", -12.5, 4.0, floor=2, heading_deg=90.0, tilt_deg=10.0), "hall", KEY)
    assert "heading 90.00 deg where the venue file has 180.00 deg" in reason(turned)
    # Same direction written differently is not stale.
    assert decode(encode(Stand("lift-3", -12.5, 4.0, 2, -180.0, 10.0), "hall", KEY), "hall", KEY, STANDS).id == "lift-3"


@pytest.mark.parametrize("text, expected", [
    ("https://example.com/menu", "not a reckon stand code (it starts 'https://exam'"),
    ("RKSx:hall", "not a reckon stand code (it starts 'RKSx'"),
    ("RKS2:hall:entrance:330:3355:0:-9000:0:NVFeNisYtVY", "unsupported stand code version 2"),
    ("RKS1:hall:entrance:330:3355", "malformed stand code: 5 fields, expected 9"),
    ("RKS1:hall:entrance:33a:3355:0:-9000:0:NVFeNisYtVY", "malformed field x_cm: '33a' is not a whole number"),
    ("RKS1:hall:entrance:330:3355:0:-9000:9001:NVFeNisYtVY", "malformed field tilt_cdeg: 9001 is outside [-9000, 9000]"),
    ("RKS1:hall:entr ance:330:3355:0:-9000:0:NVFeNisYtVY", "malformed field stand_id: 'entr ance'"),
    ("RKS1:hall:entrance:330:3355:0:-9000:0:short", "malformed field tag: 'short'"),
    ("RKS1:" + "x" * 400, "not a reckon stand code (405 characters"),
])
def test_plain_reasons_for_bad_text(text, expected):
    assert reason(text).startswith(expected)


def test_encode_refuses_what_cannot_be_a_code():
    with pytest.raises(ConfigError, match="venue 'a b'"):
        encode(ENTRANCE, "a b", KEY)
    with pytest.raises(ConfigError, match="stand 'far': malformed field x_cm: 2000000 is outside"):
        encode(Stand("far", 2e4, 0.0), "hall", KEY)
    with pytest.raises(ConfigError, match="stand key: expected 32 bytes, got 5"):
        encode(ENTRANCE, "hall", b"short")


def test_scan_message_accepted_and_refused():
    accepted = scan_message(encode(LIFT, "hall", KEY), 123, "walker", "phone", "hall", KEY, STANDS)
    assert accepted.accepted and accepted.reason == "" and accepted.stand_id == "lift-3"
    assert (accepted.x_m, accepted.y_m, accepted.floor) == (-12.5, 4.0, 2)
    assert accepted.heading_rad == pytest.approx(math.pi) and accepted.tilt_rad == pytest.approx(math.radians(10))
    assert accepted.timestamp_ns == 123 and accepted.schema_version == 1
    forged = encode(LIFT, "hall", OTHER_KEY)
    refused = scan_message(forged, 456, "walker", "phone", "hall", KEY, STANDS)
    assert not refused.accepted and refused.payload == forged and refused.reason.startswith("integrity code")
    assert refused.stand_id == "" and refused.x_m == 0.0  # nothing from an untrusted code


# ---------------------------------------------------------------------------------------------
# The key file


def test_key_file_is_private_and_never_overwritten(tmp_path):
    path = tmp_path / "hall.standkey"
    key = new_key()
    assert len(key) == 32 and key != new_key()
    write_key(path, key)
    if os.name == "posix":
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert load_key(path) == key
    with pytest.raises(ConfigError, match=f"{path}: a stand key file is already there; not overwriting"):
        write_key(path, new_key())
    assert load_key(path) == key


def test_key_file_errors_name_the_path(tmp_path):
    with pytest.raises(ConfigError, match=f"{tmp_path / 'missing.standkey'}: no stand key file there"):
        load_key(tmp_path / "missing.standkey")
    short = tmp_path / "short.standkey"
    short.write_text("abcd\n")
    with pytest.raises(ConfigError, match=f"{short}: expected 64 hex digits \\(a 32-byte key\\), found 4 characters"):
        load_key(short)
    binary = tmp_path / "binary.standkey"
    binary.write_bytes(bytes(range(128, 160)))
    with pytest.raises(ConfigError, match=f"{binary}: not a stand key file"):
        load_key(binary)


# ---------------------------------------------------------------------------------------------
# Printable codes and reading them back


def photo_of(path: Path, seed: int = 7) -> np.ndarray:
    """The code as a phone camera might see it: smaller, turned 6 degrees, on a grey desk with
    uneven light, blurred, noisy and JPEG-compressed."""
    rng = np.random.default_rng(seed)
    code = Image.open(path).convert("RGB")
    code = code.resize((int(code.width * 0.45), int(code.height * 0.45)), Image.Resampling.BILINEAR)
    code = code.rotate(6.0, resample=Image.Resampling.BILINEAR, expand=True, fillcolor=(120, 120, 110))
    scene = Image.new("RGB", (code.width + 200, code.height + 160), (120, 120, 110))
    scene.paste(code, (90, 70))
    scene = scene.filter(ImageFilter.GaussianBlur(1.2))
    pixels = np.asarray(scene, dtype=float)
    light = np.linspace(0.75, 1.0, pixels.shape[1])[None, :, None]  # a lamp on one side
    pixels = np.clip(pixels * light + rng.normal(0.0, 12.0, pixels.shape), 0, 255).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="JPEG", quality=60)
    return np.asarray(Image.open(buffer))


@pytest.fixture(scope="module")
def codes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("qr")
    return qr.make_codes(Session(Venue("hall", stands=STANDS), agents=()), KEY, folder)


def test_make_codes_writes_png_and_svg_per_stand(codes):
    assert [p.name for p in codes] == ["hall-entrance.png", "hall-entrance.svg", "hall-lift-3.png", "hall-lift-3.svg"]
    png = Image.open(codes[0])
    assert png.info["dpi"] == pytest.approx((304.8, 304.8), abs=0.1)  # 12 px per module: 1 mm at 100 %
    svg = ElementTree.parse(codes[1]).getroot()
    namespace = "{http://www.w3.org/2000/svg}"
    texts = [t.text for t in svg.iter(f"{namespace}text")]
    assert texts == ["hall / stand entrance", "x 3.30 m  y 33.55 m  floor 0", "heading -90.0 deg  tilt 0.0 deg"]
    assert svg.get("width").endswith("mm") and svg.find(f".//{namespace}path") is not None


def test_png_reads_back_also_as_a_phone_photo(codes):
    assert qr.decode_image(codes[0]) == [encode(ENTRANCE, "hall", KEY)]
    photo = photo_of(codes[2])
    assert qr.decode_image(photo) == [encode(LIFT, "hall", KEY)]
    assert decode(qr.decode_image(photo)[0], "hall", KEY, STANDS) == LIFT


def test_a_glare_spot_over_the_data_still_reads(codes):
    """Level Q's reason: a bright reflection on the stand's plate, 17 x 12 modules over the data,
    wipes about 10 % of the symbol (level M fails at this size, version for version)."""
    image = Image.open(codes[0]).convert("L")
    centre_x, centre_y, radius_px = image.width / 2, 0.6 * 45 * 12, 100
    ImageDraw.Draw(image).ellipse((centre_x - radius_px, centre_y - 0.7 * radius_px, centre_x + radius_px,
                                   centre_y + 0.7 * radius_px), fill=255)
    assert qr.decode_image(np.asarray(image)) == [encode(ENTRANCE, "hall", KEY)]


def test_decode_image_errors(tmp_path):
    not_image = hall(tmp_path / "venue.toml")
    with pytest.raises(InputError, match=f"{not_image}: not an image"):
        qr.decode_image(not_image)
    with pytest.raises(InputError, match="no such file"):
        qr.decode_image(tmp_path / "missing.png")
    with pytest.raises(InputError, match="dtype float64: expected uint8"):
        qr.decode_image(np.zeros((10, 10)))
    assert qr.decode_image(np.full((50, 50), 255, dtype=np.uint8)) == []


def test_make_codes_needs_stands():
    with pytest.raises(ConfigError, match="venue 'gym' lists no stands"):
        qr.make_codes(Session(Venue("gym"), agents=()), KEY, "unused")


# ---------------------------------------------------------------------------------------------
# reckon qr make | read


def command(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="reckon")
    qr_command.register(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["qr", *argv])


def test_qr_make_creates_the_key_once_and_read_checks_codes(tmp_path, capsys):
    venue = hall(tmp_path / "venue.toml")
    out = tmp_path / "codes"
    args = command("make", str(venue), "-o", str(out))
    assert args.run(args, print) == 0
    printed = capsys.readouterr().out
    key_path = tmp_path / "hall.standkey"
    assert f"created a new stand key in {key_path}. It is a secret" in printed
    key = load_key(key_path)
    args = command("make", str(venue), "-o", str(out))
    assert args.run(args, print) == 0
    assert "created" not in capsys.readouterr().out and load_key(key_path) == key  # reused, not replaced

    foreign = qr.make_codes(Session(Venue("hall", stands=(ENTRANCE,)), agents=()), OTHER_KEY, tmp_path / "foreign")
    args = command("read", str(out / "hall-lift-3.png"), str(foreign[0]), "--venue", str(venue))
    assert args.run(args, print) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].endswith("hall-lift-3.png: stand lift-3: x -12.50 m, y 4.00 m, floor 2, heading 180.00 deg, "
                             "tilt 10.00 deg")
    assert lines[1].endswith("hall-entrance.png: refused: integrity code does not match: the code was altered, "
                             "forged, or made with another key than this venue's")


def test_qr_read_with_a_missing_key_file_names_it(tmp_path):
    venue = hall(tmp_path / "venue.toml")
    args = command("read", "any.png", "--venue", str(venue), "--key-file", str(tmp_path / "none.standkey"))
    with pytest.raises(ConfigError, match="none.standkey: no stand key file there"):
        args.run(args, print)

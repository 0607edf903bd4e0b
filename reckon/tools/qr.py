"""Calibration stands' QR codes: printable PNG and SVG per stand and reading codes back from
images, the work behind `reckon qr make|read` (its parser is reckon/cli/qr.py; docs/qr-stands.md).
The code's text and its integrity check live in protocol/stand_code.py and the key file in
edge/sources/phone/stand_key.py; this module only draws and reads pictures of it.

Print geometry: 1 mm per QR module (a typical stand's code, version 5, is 37 modules plus a
4-module quiet zone each side: 45 mm). Phone cameras read a 1 mm module comfortably from 10 cm to
about 50 cm, which covers a phone lying in the stand's corner and one held at arm's length.
Error correction level Q (25 % of the symbol may be lost): a code behind a transparent plate gets
glare and scratches, and Q costs one or two versions over M for a 50-80 character text.
"""

from __future__ import annotations

import argparse
import io
import sys
from collections.abc import Callable
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np
import segno
import zxingcpp
from PIL import Image, ImageDraw, ImageFont, UnidentifiedImageError

from protocol.errors import ConfigError, InputError
from protocol.session import Session, Stand, load_toml
from protocol.stand_code import StandCodeError, decode, encode, new_key
from edge.sources.phone.stand_key import key_path, load_key, write_key

ERROR_LEVEL = "q"
QUIET_ZONE_MODULES = 4  # the QR standard's minimum; less and scanners miss the finder patterns
MODULE_MM = 1.0
PNG_MODULE_PX = 12
PNG_DPI = PNG_MODULE_PX * 25.4 / MODULE_MM  # 304.8 dpi: the PNG prints at exactly 1 mm per module at 100 %
CAPTION_PX = 36  # 3 mm at 304.8 dpi: readable at arm's length
CAPTION_MM = 3.0
MONOSPACE_WIDTH_EM = 0.6  # advance of one monospace character, to size the SVG without rendering it


def _caption(venue: str, stand: Stand) -> list[str]:
    return [f"{venue} / stand {stand.id}",
            f"x {stand.x_m:.2f} m  y {stand.y_m:.2f} m  floor {stand.floor}",
            f"heading {stand.heading_deg:.1f} deg  tilt {stand.tilt_deg:.1f} deg"]


def _symbol(text: str) -> segno.QRCode:
    # Byte mode: ids are case-sensitive, so the denser alphanumeric mode (upper case only) cannot
    # hold them. segno picks the smallest version and raises the level above Q when that fits free.
    return segno.make(text, error=ERROR_LEVEL, mode="byte", micro=False)


def _write_png(symbol: segno.QRCode, caption: list[str], path: Path) -> Path:
    buffer = io.BytesIO()
    symbol.save(buffer, kind="png", scale=PNG_MODULE_PX, border=QUIET_ZONE_MODULES)
    code = Image.open(buffer).convert("L")
    font = ImageFont.load_default(size=CAPTION_PX)
    line_px = int(CAPTION_PX * 1.3)
    margin_px = PNG_MODULE_PX * QUIET_ZONE_MODULES
    width = max(code.width, max(int(font.getlength(line)) for line in caption) + 2 * margin_px)
    page = Image.new("L", (width, code.height + line_px * len(caption) + margin_px), 255)  # white: the light modules
    page.paste(code, ((width - code.width) // 2, 0))
    draw = ImageDraw.Draw(page)
    for row, line in enumerate(caption):
        draw.text((width / 2, code.height + row * line_px), line, fill=0, font=font, anchor="mt")
    page.save(path, dpi=(PNG_DPI, PNG_DPI))
    return path


def _write_svg(symbol: segno.QRCode, caption: list[str], title: str, path: Path) -> Path:
    code_mm = symbol.symbol_size(scale=MODULE_MM, border=QUIET_ZONE_MODULES)[0]
    margin_mm = MODULE_MM * QUIET_ZONE_MODULES
    line_mm = CAPTION_MM * 1.3
    width_mm = max(code_mm, max(len(line) for line in caption) * CAPTION_MM * MONOSPACE_WIDTH_EM + 2 * margin_mm)
    height_mm = code_mm + line_mm * len(caption) + margin_mm
    code = symbol.svg_inline(scale=MODULE_MM, border=QUIET_ZONE_MODULES)
    lines = "\n".join(
        f'<text x="{width_mm / 2:.2f}" y="{code_mm + (row + 0.8) * line_mm:.2f}" font-size="{CAPTION_MM}" '
        f'font-family="DejaVu Sans Mono, Menlo, monospace" text-anchor="middle">{escape(line)}</text>'
        for row, line in enumerate(caption))
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width_mm:.2f}mm" height="{height_mm:.2f}mm" '
        f'viewBox="0 0 {width_mm:.2f} {height_mm:.2f}">\n'
        f"<title>{escape(title)}</title>\n"
        # An opaque white ground: on a transparent stand the light modules must still be light.
        '<rect width="100%" height="100%" fill="#fff"/>\n'
        f'<g transform="translate({(width_mm - code_mm) / 2:.2f} 0)">{code}</g>\n'
        f"{lines}\n</svg>\n", encoding="utf-8")
    return path


def make_codes(session: Session, key: bytes, out_dir: Path | str) -> list[Path]:
    """Write `<venue>-<stand>.png` and `.svg` into `out_dir` (created) for every stand of the
    session's venue; returns the paths, PNG then SVG per stand. ConfigError if there are none."""
    venue = session.venue
    if not venue.stands:
        raise ConfigError(f"venue {venue.name!r} lists no stands: add [[venue.stands]] tables to the venue file "
                          "(docs/qr-stands.md)")
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for stand in venue.stands:
        symbol = _symbol(encode(stand, venue.name, key))
        caption = _caption(venue.name, stand)
        name = f"{venue.name}-{stand.id}"  # ids hold no dots or slashes: a safe file name
        paths.append(_write_png(symbol, caption, folder / f"{name}.png"))
        paths.append(_write_svg(symbol, caption, f"reckon stand {stand.id} of {venue.name}", folder / f"{name}.svg"))
    return paths


def _gray(image: Path | str | np.ndarray) -> np.ndarray:
    if isinstance(image, (str, Path)):
        try:
            with Image.open(image) as picture:
                return np.asarray(picture.convert("L"))
        except FileNotFoundError:
            raise InputError(f"{image}: no such file") from None
        except UnidentifiedImageError:  # before OSError: it is one
            raise InputError(f"{image}: not an image (PNG, JPEG or another format pillow reads; "
                             "an SVG must be rasterised first)") from None
        except OSError as error:
            raise InputError(f"{image}: cannot read the image ({error})") from None
    pixels = np.asarray(image)
    if pixels.dtype != np.uint8 or pixels.ndim not in (2, 3) or (pixels.ndim == 3 and pixels.shape[2] not in (3, 4)):
        raise InputError(f"image array of shape {pixels.shape} and dtype {pixels.dtype}: expected uint8, "
                         "height x width (gray) or height x width x 3/4 (RGB/RGBA)")
    return np.asarray(Image.fromarray(pixels).convert("L"))


def decode_image(image: Path | str | np.ndarray) -> list[str]:
    """The texts of every QR code found in an image file or array (empty if none).
    InputError naming the file when it is missing or not an image, or for an unusable array."""
    found = zxingcpp.read_barcodes(_gray(image), formats=zxingcpp.BarcodeFormat.QRCode,
                                   text_mode=zxingcpp.TextMode.Plain)
    return [barcode.text for barcode in found if barcode.valid]


# ---------------------------------------------------------------------------------------------
# reckon qr make | read


def _key_path(args: argparse.Namespace, session: Session) -> Path:
    return key_path(Path(args.venue).parent, session.venue.name, args.key_file)


def _describe(stand: Stand) -> str:
    return (f"stand {stand.id}: x {stand.x_m:.2f} m, y {stand.y_m:.2f} m, floor {stand.floor}, "
            f"heading {stand.heading_deg:.2f} deg, tilt {stand.tilt_deg:.2f} deg")


# The CLI calls every command as run(args, progress); both commands take well under a second, so
# they print no progress.
def run_make(args: argparse.Namespace, progress: Callable[[str], None] | None = None) -> int:
    session = load_toml(Path(args.venue))
    key_path = _key_path(args, session)
    if key_path.exists():
        key = load_key(key_path)
    else:
        key = new_key()
        write_key(key_path, key)
        print(f"created a new stand key in {key_path}. It is a secret: anyone who has it can print stand codes "
              "your phones will trust. Keep it out of version control, back it up, and give it only to the "
              "edges that check scans.")
    paths = make_codes(session, key, Path(args.output))
    for path in paths:
        print(path)
    print(f"{len(paths) // 2} stands of venue {session.venue.name!r}: print at 100 % scale on opaque white "
          f"paper ({MODULE_MM:g} mm per module, docs/qr-stands.md)")
    return 0


def run_read(args: argparse.Namespace, progress: Callable[[str], None] | None = None) -> int:
    """One line per code found: the stand, or `refused:` and why. Status 1 if any image gave no
    accepted stand (no code, a refused code, or not an image)."""
    session = load_toml(Path(args.venue))
    key = load_key(_key_path(args, session))
    status = 0
    for image in args.images:
        try:
            texts = decode_image(Path(image))
        except InputError as error:
            print(f"reckon: error: {error}", file=sys.stderr)
            status = 1
            continue
        if not texts:
            print(f"{image}: no QR code found")
            status = 1
        for text in texts:
            try:
                print(f"{image}: {_describe(decode(text, session.venue.name, key, session.venue.stands))}")
            except StandCodeError as error:
                print(f"{image}: refused: {error.reason}")
                status = 1
    return status

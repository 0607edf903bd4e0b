"""A camera frame from the phone page -> the text of the QR stand code in it (docs/phone.md), read
with zxing-cpp. Pure: no socket, no clock (times are the phone's, from the message).

`decode_frame(jpeg, width, height)` is the stateless step: the text of the first QR code in the
frame, None when there is none, QrFrameError naming the value and the limit for a frame that is
not a usable JPEG of the size it claims. `QrFrameReader` wraps it for one page's stream: it counts
every outcome, turns a bad frame into a problem (the stream goes on) and, like the page does for
codes it reads itself, passes the same code on again only after SAME_CODE_AGAIN_NS of phone time,
so a stand held in view for a while is one scan, not one per frame.
"""

from __future__ import annotations

import enum
import io
from dataclasses import dataclass

import numpy as np
import zxingcpp
from PIL import Image, UnidentifiedImageError

from edge.decoders.phone.parse import SCAN_TEXT_CHARS, PhoneInputError

# The page sends frames at most 640 px on the long side; 1024 leaves room for a page that sends
# more and still bounds what one frame costs to decode (~1 M pixels, a few ms in zxing-cpp).
MAX_FRAME_SIDE_PX = 1024
MIN_FRAME_SIDE_PX = 21  # a version-1 QR code is 21 modules: a smaller frame cannot hold one
MAX_FRAME_BYTES = 600_000  # a 1024 x 1024 JPEG at quality 0.9 is ~300 KB; base64 of this fits a 1 MiB message
JPEG_START = b"\xff\xd8\xff"  # SOI marker and the first segment's marker
SAME_CODE_AGAIN_NS = 5_000_000_000  # as the page's SAME_CODE_AGAIN_MS for codes it reads itself


class QrFrameError(PhoneInputError):
    """A frame that cannot be decoded; `reason` names the value and the limit."""


class FrameOutcome(enum.Enum):
    """What one frame gave: a code to scan, the code just scanned again, no code, or a bad frame."""

    CODE = "code"
    REPEAT = "repeat"
    NO_CODE = "none"
    BAD = "bad"


def _check_side(name: str, value: int) -> None:
    if not MIN_FRAME_SIDE_PX <= value <= MAX_FRAME_SIDE_PX:
        raise QrFrameError(f"frame {name} {value} px is outside [{MIN_FRAME_SIDE_PX}, {MAX_FRAME_SIDE_PX}]")


def _grey_pixels(jpeg: bytes, width: int, height: int) -> np.ndarray:
    """The frame as height x width uint8 grey; QrFrameError if it is not that JPEG."""
    if not jpeg.startswith(JPEG_START):
        raise QrFrameError(f"frame of {len(jpeg)} bytes does not start as a JPEG (got {jpeg[:3].hex() or 'nothing'}, "
                           f"expected {JPEG_START.hex()})")
    try:
        # open() reads only the header: the size is checked before any pixel is decoded.
        with Image.open(io.BytesIO(jpeg), formats=["JPEG"]) as image:
            if image.size != (width, height):
                raise QrFrameError(f"frame is {image.width} x {image.height} px, the message says {width} x {height}")
            return np.asarray(image.convert("L"))
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as error:
        # pillow raises OSError for a truncated or corrupt JPEG, SyntaxError/ValueError for bad markers
        raise QrFrameError(f"frame of {len(jpeg)} bytes is not a readable JPEG ({error})") from None


def decode_frame(jpeg: bytes, width: int, height: int) -> str | None:
    """The text of the first valid QR code in a JPEG frame of `width` x `height` px, or None if it
    shows none. QrFrameError for a side outside [MIN_FRAME_SIDE_PX, MAX_FRAME_SIDE_PX], more than
    MAX_FRAME_BYTES, bytes that are not such a JPEG, or a code over SCAN_TEXT_CHARS characters
    (no stand code is that long; the scan message has the same limit)."""
    _check_side("width", width)
    _check_side("height", height)
    if len(jpeg) > MAX_FRAME_BYTES:
        raise QrFrameError(f"frame of {len(jpeg)} bytes exceeds {MAX_FRAME_BYTES}")
    found = zxingcpp.read_barcodes(_grey_pixels(jpeg, width, height), formats=zxingcpp.BarcodeFormat.QRCode,
                                   text_mode=zxingcpp.TextMode.Plain)
    text = next((barcode.text for barcode in found if barcode.valid and barcode.text), None)
    if text is not None and len(text) > SCAN_TEXT_CHARS:
        raise QrFrameError(f"QR code of {len(text)} characters exceeds {SCAN_TEXT_CHARS}")
    return text


@dataclass
class FrameCounts:
    """Frames from one page and what each gave; every field a count."""

    frames: int = 0
    codes: int = 0  # passed on to be scanned
    repeats: int = 0  # the code last passed on, again within SAME_CODE_AGAIN_NS
    no_code: int = 0
    bad_frames: int = 0


class QrFrameReader:
    """One page's frames -> stand code texts to scan. State: the counts and the last code passed on."""

    def __init__(self, same_code_again_ns: int = SAME_CODE_AGAIN_NS):
        self.same_code_again_ns = same_code_again_ns
        self.counts = FrameCounts()
        self._last_text = ""
        self._last_ns: int | None = None

    def feed(self, time_ns: int, jpeg: bytes, width: int, height: int,
             problems: list[str]) -> tuple[FrameOutcome, str | None]:
        """(outcome, text to scan or None) for the frame taken at `time_ns` (phone clock). A bad
        frame is counted and its reason appended to `problems`; it never raises."""
        self.counts.frames += 1
        try:
            text = decode_frame(jpeg, width, height)
        except QrFrameError as error:
            self.counts.bad_frames += 1
            problems.append(error.reason)
            return FrameOutcome.BAD, None
        if text is None:
            self.counts.no_code += 1
            return FrameOutcome.NO_CODE, None
        if (text == self._last_text and self._last_ns is not None
                and 0 <= time_ns - self._last_ns < self.same_code_again_ns):
            self.counts.repeats += 1
            return FrameOutcome.REPEAT, None
        self._last_text, self._last_ns = text, time_ns
        self.counts.codes += 1
        return FrameOutcome.CODE, text

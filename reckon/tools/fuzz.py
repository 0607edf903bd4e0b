"""`reckon fuzz`: the push decoders against mutated streams, counting crashes and lost frames.

A stream is built of units: an intact frame (its decoded values known from the encoder), or a
mutation: random garbage (rich in the decoder's sync bytes), an intact frame with bytes replaced,
one cut short, one with a byte inserted or deleted, or an intact frame sent twice. The bytes
are fed in chunks of random size. A crash is any exception out of `feed`/`reset` (none is
documented: decoders never raise on stream content). An intact frame counts as recovered when
the decoded frames hold it, with its values, in order (a subsequence match): "every intact
frame after the garbage recovered".

Decoders: every byte-stream decoder that declares a fuzz hook (`DEVICE` in its module,
edge/decoders/devices.py): `tsnd` (TsndDecoder, 0x80/0x81 frames from
sim_devices/devices/tsnd_encoder.py), `ximu3` (Ximu3Decoder, binary and ASCII I/M messages from
sim_devices/devices/ximu3_encoder.py); and `ble` (ThingyMotionDecoder notifications, datagrams
rather than a stream, and the iBeacon/Eddystone advertisement parsers fed random manufacturer and
service data). Engines: `random` (seeded, numpy) and, where the optional
`atheris` package installs, `atheris` (libFuzzer's coverage-guided mutations of whole streams).
"""

from __future__ import annotations

import importlib
import sys
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from edge.decoders.ble_adverts import (APPLE_COMPANY_ID, EDDYSTONE_SERVICE_UUID, THINGY_RAW_MOTION, ThingyMotionDecoder,
                                       parse_eddystone_uid, parse_ibeacon)
from edge.decoders.devices import DeviceDecoder, device_decoders
from edge.decoders.ximu3 import InertialFrame, MagnetometerFrame
from protocol.errors import ConfigError

# The byte-stream decoders with a fuzz hook, then the BLE datagrams
STREAMS: dict[str, DeviceDecoder] = {name: device for name, device in device_decoders().items()
                                     if device.new_decoder is not None and device.fuzz_frames}
DECODERS = (*STREAMS, "ble")
MUTATION_SHARE = 0.5  # of the units, the rest are intact frames
MAX_CHUNK_BYTES = 4096
UNITS_PER_BLOCK = 20_000  # frames encoded at once (vectorised), then mutated and fed


@dataclass
class FuzzResult:
    decoder: str
    frames: int = 0  # units sent: intact frames and mutations
    mutations: int = 0
    crashes: int = 0
    intact_sent: int = 0
    intact_recovered: int = 0
    seconds: float = 0.0
    first_crash: str = ""
    mutation_counts: dict[str, int] = field(default_factory=dict)

    def __str__(self) -> str:
        rate = self.frames / self.seconds if self.seconds else 0.0
        kinds = ", ".join(f"{name} {count}" for name, count in sorted(self.mutation_counts.items()))
        text = (f"{self.decoder}: {self.frames} frames, {self.mutations} mutations ({kinds}), {self.crashes} crashes, "
                f"intact frames recovered {self.intact_recovered} / {self.intact_sent}, {rate:,.0f} frames/s")
        return text + (f"\n  first crash:\n{self.first_crash}" if self.first_crash else "")


def _key(frame: Any) -> tuple | None:
    """What must survive of a decoded sample frame: time and values, rounded to the wire's steps."""
    if isinstance(frame, InertialFrame):
        return ("I", frame.timestamp_us, *(round(v, 3) for v in frame.gyro_dps + frame.accel_g))
    if isinstance(frame, MagnetometerFrame):
        return ("M", frame.timestamp_us, *(round(v, 3) for v in frame.mag_au))
    return None


def _mutate(rng: np.random.Generator, frame: bytes, sync: bytes, counts: dict[str, int]) -> bytes:
    kind = ("garbage", "replace", "truncate", "insert", "delete", "duplicate")[int(rng.integers(0, 6))]
    counts[kind] = counts.get(kind, 0) + 1
    if kind == "garbage":
        garbage = bytearray(rng.integers(0, 256, int(rng.integers(1, 65)), dtype=np.uint8).tobytes())
        for _ in range(int(rng.integers(0, 4)) if sync else 0):  # sync bytes make the decoder start false frames
            garbage[int(rng.integers(0, len(garbage)))] = sync[int(rng.integers(0, len(sync)))]
        return bytes(garbage)
    data = bytearray(frame)
    at = int(rng.integers(0, len(data)))
    if kind == "replace":
        for _ in range(int(rng.integers(1, 4))):
            data[int(rng.integers(0, len(data)))] = int(rng.integers(0, 256))
    elif kind == "truncate":
        del data[at:]
    elif kind == "insert":
        data.insert(at, int(rng.integers(0, 256)))
    elif kind == "delete":
        del data[at]
    else:
        return frame + frame
    return bytes(data)


def _frame_maker(device: DeviceDecoder) -> Callable[[np.random.Generator, int, int], list[bytes]]:
    """The simulated device's encoder hook the decoder names ("module:function")."""
    module, _, function = device.fuzz_frames.partition(":")
    maker: Callable[[np.random.Generator, int, int], list[bytes]] = getattr(importlib.import_module(module), function)
    return maker


def _fresh(name: str) -> Any:
    """A new decoder of stream `name` (STREAMS holds only devices that have one)."""
    new_decoder: Callable[[], Any] = STREAMS[name].new_decoder  # type: ignore[assignment]
    return new_decoder()


def _expected(name: str, frame: bytes) -> tuple | None:
    """The key of an intact frame, decoded alone by a fresh decoder."""
    frames = _fresh(name).feed(frame)
    return _key(frames[0]) if frames else None


def _stream_decoder(name: str, frames: int, seed: int) -> FuzzResult:
    rng = np.random.default_rng(seed)
    result = FuzzResult(name)
    decoder = _fresh(name)
    make = _frame_maker(STREAMS[name])
    sync = STREAMS[name].sync_bytes
    start_ms, begun = 3_600_000, time.perf_counter()
    while result.frames < frames:
        count = min(UNITS_PER_BLOCK, frames - result.frames)
        intact = make(rng, start_ms, count)[:count]  # the magnetometer frames count too
        start_ms += count
        mutate = rng.random(len(intact)) < MUTATION_SHARE
        parts, expected = [], []
        for frame, damaged in zip(intact, mutate):
            if damaged:
                parts.append(_mutate(rng, frame, sync, result.mutation_counts))
                result.mutations += 1
            else:
                parts.append(frame)
                expected.append(_expected(name, frame))
            result.frames += 1
        data = b"".join(parts)
        decoded = _feed_chunks(rng, decoder, data, result)
        result.intact_sent += len(expected)
        result.intact_recovered += _subsequence(expected, decoded)
    result.seconds = time.perf_counter() - begun
    return result


def _feed_chunks(rng: np.random.Generator, decoder: Any, data: bytes, result: FuzzResult) -> list[tuple]:
    keys: list[tuple] = []
    position = 0
    while position < len(data):
        size = int(rng.integers(1, MAX_CHUNK_BYTES + 1))
        keys += _call(result, decoder.feed, data[position:position + size])
        position += size
    return keys


def _call(result: FuzzResult, work: Callable[..., list[Any]], *args: Any) -> list[tuple]:
    try:
        frames = work(*args)
    except Exception:  # what the fuzzer is looking for: counted and shown, the run goes on
        result.crashes += 1
        result.first_crash = result.first_crash or traceback.format_exc()
        return []
    return [key for key in map(_key, frames) if key is not None]


def _subsequence(expected: list[tuple | None], decoded: list[tuple]) -> int:
    """How many of `expected` appear in `decoded` in order. Intact frames have distinct times, so
    each key has one place; decoded frames not expected are mutations that still decoded."""
    places = {key: index for index, key in enumerate(expected) if key is not None}
    found, last = 0, -1
    for key in decoded:
        index = places.get(key, -1)
        if index > last:
            found += 1
            last = index
    return found


def _ble(frames: int, seed: int) -> FuzzResult:
    """Thingy:52 notifications (each stands alone: a mutation is a wrong length or random
    content) and advertisement parsers fed random records."""
    rng = np.random.default_rng(seed)
    result = FuzzResult("ble")
    decoder = ThingyMotionDecoder()
    begun, receive_ns = time.perf_counter(), 10**18
    for _ in range(frames):
        receive_ns += 5_000_000
        result.frames += 1
        values = rng.integers(-32768, 32768, 9)
        intact = THINGY_RAW_MOTION.pack(*values.tolist())
        if rng.random() < MUTATION_SHARE:
            result.mutations += 1
            data = _mutate(rng, intact, b"", result.mutation_counts)
            _call(result, decoder.feed, data, receive_ns)
            advert = _random_advert(rng, intact)
            _call(result, _parse_advert, advert)
            continue
        result.intact_sent += 1
        keys = _call(result, decoder.feed, intact, receive_ns)
        gyro = tuple(round(v / 32, 3) for v in values[3:6].tolist())
        if keys and keys[-1][2:5] == gyro:
            result.intact_recovered += 1
    result.seconds = time.perf_counter() - begun
    return result


def _parse_advert(advert: tuple[Any, Any]) -> list[Any]:
    parse_ibeacon(advert[0])
    parse_eddystone_uid(advert[1])
    return []


def _random_advert(rng: np.random.Generator, payload: bytes) -> tuple[Any, Any]:
    """Manufacturer and service data as a radio might hand them over, mostly wrong."""
    body = payload[:int(rng.integers(0, len(payload) + 1))] + b"\x02\x15" * int(rng.integers(0, 2))
    choice = int(rng.integers(0, 4))
    if choice == 0:
        return {APPLE_COMPANY_ID: b"\x02\x15" + body}, {EDDYSTONE_SERVICE_UUID.upper(): b"\x00" + body}
    if choice == 1:
        return {APPLE_COMPANY_ID: bytearray(body), 7: None}, {"x": body, 5: body}
    if choice == 2:
        return None, [body]  # not mappings at all
    return {APPLE_COMPANY_ID: "text"}, {EDDYSTONE_SERVICE_UUID: memoryview(body)}


def run_fuzz(decoder: str, frames: int, seed: int) -> list[FuzzResult]:
    """Fuzz one decoder or `all`; a result per decoder."""
    names = DECODERS if decoder == "all" else (decoder,)
    if any(name not in DECODERS for name in names):
        raise ConfigError(f"--decoder {decoder!r}: one of {', '.join(DECODERS)}, all")
    if not 1 <= frames <= 10**9:
        raise ConfigError(f"--frames {frames}: outside [1, 1000000000]")
    return [_ble(frames, seed) if name == "ble" else _stream_decoder(name, frames, seed) for name in names]


def run_atheris(decoder: str, frames: int) -> int:
    """libFuzzer through atheris over `frames` inputs: each input is a whole stream fed to a fresh
    decoder in two chunks; any exception is a crash (atheris stops and prints the input)."""
    try:
        import atheris  # optional: `pip install atheris` (a wheel exists for CPython on x86-64 Linux)
    except ImportError:
        raise ConfigError("--engine atheris: the atheris package is not installed (pip install atheris)") from None
    names = DECODERS if decoder == "all" else (decoder,)

    def one_input(data: bytes) -> None:
        cut = len(data) // 2
        for name in names:
            if name == "ble":
                ThingyMotionDecoder().feed(data, 1)
                parse_ibeacon({APPLE_COMPANY_ID: data})
                parse_eddystone_uid({EDDYSTONE_SERVICE_UUID: data})
                continue
            stream = _fresh(name)
            stream.feed(data[:cut])
            stream.feed(data[cut:])
            stream.reset()

    atheris.instrument_all()  # coverage of the decoders' bytecode, already imported above
    atheris.Setup([sys.argv[0], f"-runs={frames}", "-max_len=4096"], one_input)
    atheris.Fuzz()
    return 0

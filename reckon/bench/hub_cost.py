"""What the hub pays per message in Python, without Zenoh: its recorded inputs fed again to a ChairHub."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema

from hub.chair.hub import ChairHub
from protocol import bus as wire
from protocol import messages
from protocol.session import Session
from protocol.session_log import SessionWriter, iter_records
from reckon.bench.play import HUB_INPUTS, stream_of


def hub_profile(recording: Path, session: Session, scratch: Path) -> dict[str, Any]:
    """Feed the hub's recorded inputs, in order, to a fresh ChairHub: mean microseconds per step."""
    problems: list[str] = []
    names: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    inputs: list[tuple[str, str, bytes, int]] = []
    for record in iter_records(recording, problems):
        if isinstance(record, Schema):
            names[record.id] = record.name.removeprefix(messages.PACKAGE + ".")
        elif isinstance(record, Channel):
            channels[record.id] = (record.topic, names.get(record.schema_id, ""))
        elif isinstance(record, Message):
            topic, name = channels[record.channel_id]
            if stream_of(topic) in HUB_INPUTS:
                inputs.append((topic, name, record.data, record.log_time))
    hub = ChairHub(session)
    decode: dict[str, list[int]] = {}
    compute: dict[str, list[int]] = {}
    encode_ns = write_ns = outputs = 0
    clock = time.perf_counter_ns
    with SessionWriter(scratch, session) as writer:
        for topic, name, payload, arrival_ns in inputs:
            began = clock()
            message = messages.CLASSES[name].FromString(payload)
            decoded = clock()
            results = hub.on_message(message, arrival_ns)
            computed = clock()
            writer.write(topic, message, decoded)
            for out in results:
                writer.write(hub.key_for(out), out, computed)
            written = clock()
            for out in results:
                wire.encode(out)
            encode_ns += clock() - written
            write_ns += written - computed
            outputs += len(results)
            decode.setdefault(name, [0, 0])[0] += decoded - began
            decode[name][1] += 1
            compute.setdefault(name, [0, 0])[0] += computed - decoded
            compute[name][1] += 1
    scratch.unlink(missing_ok=True)
    count = len(inputs)
    total_ns = sum(v[0] for v in decode.values()) + sum(v[0] for v in compute.values()) + encode_ns + write_ns
    return {
        "inputs": {name: n for name, (_, n) in compute.items()}, "outputs": outputs,
        "decode": {name: 1e-3 * ns / n for name, (ns, n) in decode.items()},
        "chair_hub": {name: 1e-3 * ns / n for name, (ns, n) in compute.items()},
        "encode_per_output": 1e-3 * encode_ns / max(1, outputs),
        "record_per_message": 1e-3 * write_ns / max(1, count + outputs),
        "python_per_input": 1e-3 * total_ns / max(1, count),
    }

#!/usr/bin/env python3
"""Did the hub put out live poses for every agent? Used by deploy/arm64-check.sh inside the arm64 root.

    python3 deploy/arm64-poses.py SESSION.mcap HUB.mcap

Counts the `pose/live` messages per agent of SESSION's description in the hub's recording HUB and
prints one line, e.g. `chair01=494 chair02=498`. Exit 0 when every agent has at least one, 1 when
one has none or the recording is damaged, 2 when a file cannot be read. Needs only reckon's core
(mcap and the protocol package), so it runs with the hub or the edge extra alone.
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

from mcap.records import Channel, Message

from protocol import keys
from protocol.errors import InputError
from protocol.session_log import iter_records, read_description


def live_poses(session_log: Path, recording: Path) -> tuple[dict[str, int], list[str]]:
    """Each agent's number of pose/live messages in `recording`, and the problems met reading it."""
    agents = [agent.id for agent in read_description(session_log).agents]
    problems: list[str] = []
    topics: dict[int, str] = {}
    counts: Counter[str] = Counter()
    for record in iter_records(recording, problems):
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message) and record.channel_id in topics:
            try:
                _, agent, stream, sub = keys.parse(topics[record.channel_id])
            except ValueError:
                continue
            if stream == "pose" and sub == "live":
                counts[agent] += 1
    return {agent: counts[agent] for agent in agents}, problems


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] in ("-h", "--help"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    try:
        counts, problems = live_poses(Path(argv[0]), Path(argv[1]))
    except InputError as error:
        print(f"arm64-poses: {error}", file=sys.stderr)
        return 2
    print(" ".join(f"{agent}={count}" for agent, count in counts.items()) or "no agents")
    for problem in problems:
        print(f"arm64-poses: {problem}", file=sys.stderr)
    return 0 if counts and all(counts.values()) and not problems else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

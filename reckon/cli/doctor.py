"""`reckon doctor`: its parser and checks are in reckon/tools/doctor.py; here it gets the bus options."""

from __future__ import annotations

from typing import Any

from reckon.cli.bus import bus_config, bus_options
from reckon.tools import doctor


def register(sub: Any) -> None:
    doctor.register(sub, bus_options, bus_config)

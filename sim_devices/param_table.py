"""Simulator parameters as a table of documented figures, shared by every simulated venue.

A simulator's parameters are one frozen dataclass of groups (frozen dataclasses of fields made by
`param`); a figure's dotted key is `<group>.<field>`. Each field's metadata holds its unit, the
accepted range and where the figure comes from, so `--set` validation, the error-free variant and
the documentation tables are driven by the same data.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, TypeVar

from protocol.errors import ConfigError

P = TypeVar("P")


def param(default: float | int, unit: str, low: float, high: float, source: str = "") -> Any:
    """A parameter field: default, unit, accepted range [low, high] and where the figure comes from."""
    return dataclasses.field(default=default, metadata={"unit": unit, "low": low, "high": high, "source": source})


def zeroed(params: P, fields_by_group: dict[str, tuple[str, ...]]) -> P:
    """`params` with the named fields of each group set to zero (of their own type)."""
    groups = {name: dataclasses.replace(getattr(params, name),
                                        **{f: type(getattr(getattr(params, name), f))(0) for f in fields})
              for name, fields in fields_by_group.items()}
    return dataclasses.replace(params, **groups)  # type: ignore[type-var]


def rows(params: Any, source: Callable[[str, dataclasses.Field[Any]], str] | None = None
         ) -> list[tuple[str, Any, str, str]]:
    """(dotted key, value, unit, source) of every figure, in declaration order. `source(group, field)`
    replaces the field's own source (figures whose sources live elsewhere)."""
    out = []
    for group in dataclasses.fields(params):
        value = getattr(params, group.name)
        for item in dataclasses.fields(value):
            text = source(group.name, item) if source else item.metadata["source"]
            out.append((f"{group.name}.{item.name}", getattr(value, item.name), item.metadata["unit"], text))
    return out


def with_overrides(params: P, overrides: dict[str, str]) -> P:
    """Apply `--set key=value` overrides (dotted keys, string values); ConfigError names the key
    when it is unknown, the value is not a number of the right type, or lies outside its range."""
    changes: dict[str, dict[str, Any]] = {}
    groups = {f.name for f in dataclasses.fields(params)}  # type: ignore[arg-type]
    for key, text in overrides.items():
        group_name, _, name = key.partition(".")
        if group_name not in groups:
            raise ConfigError(f"--set {key}: unknown group {group_name!r} (groups: {', '.join(sorted(groups))})")
        known = {f.name: f for f in dataclasses.fields(getattr(params, group_name))}
        if name not in known:
            raise ConfigError(f"--set {key}: unknown key {name!r} in {group_name} (keys: {', '.join(sorted(known))})")
        changes.setdefault(group_name, {})[name] = _parse(key, str(text), known[name])
    return dataclasses.replace(params, **{group: dataclasses.replace(getattr(params, group), **values)  # type: ignore[type-var]
                                          for group, values in changes.items()})


MAX_BATCH_SPAN_S = 4.0  # ImuBatch sample offsets are uint32 ns: at most 4.29 s


def check_pairs_and_batches(params: Any) -> None:
    """ConfigError when a `*_min`/`*_max` pair of a group is reversed, or (with a `sensors` group
    of `batch_samples` at `rate_hz`) when an ImuBatch would span more than MAX_BATCH_SPAN_S."""
    for group in dataclasses.fields(params):
        values = getattr(params, group.name)
        names = [f.name for f in dataclasses.fields(values)]
        for name in names:
            if "_min" in name:
                partner = name.replace("_min", "_max", 1)
                if partner in names and getattr(values, name) > getattr(values, partner):
                    raise ConfigError(f"--set: {group.name}.{name} = {getattr(values, name)} exceeds "
                                      f"{group.name}.{partner} = {getattr(values, partner)}")
    sensors = getattr(params, "sensors", None)
    if sensors is not None and hasattr(sensors, "batch_samples"):
        span_s = sensors.batch_samples / sensors.rate_hz
        if span_s > MAX_BATCH_SPAN_S:
            raise ConfigError(f"--set: sensors.batch_samples / sensors.rate_hz = {span_s:g} s exceeds "
                              f"{MAX_BATCH_SPAN_S} s (an ImuBatch's uint32 sample offsets)")


def _parse(key: str, text: str, spec: dataclasses.Field[Any]) -> float | int:
    low, high = spec.metadata["low"], spec.metadata["high"]
    integer = isinstance(spec.default, int) and not isinstance(spec.default, bool)
    try:
        value: float | int = int(text) if integer else float(text)
    except ValueError:
        raise ConfigError(f"--set {key}={text}: not {'an integer' if integer else 'a number'}") from None
    if not math.isfinite(value):
        raise ConfigError(f"--set {key}={text}: not a finite number")
    if not low <= value <= high:
        raise ConfigError(f"--set {key}={text}: outside [{low}, {high}] {spec.metadata['unit']}")
    return value

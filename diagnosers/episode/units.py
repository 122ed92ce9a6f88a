"""The units of an :class:`~diagnosers.episode.record.Episode`'s channels: checked, and read from data.

Units are presentation only (axis labels, table headers): no diagnoser reads them. One entry per
channel; ``""`` stands for a channel whose unit the data do not state, so a figure labels it
without a unit rather than with a guessed one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["check_units", "sidecar_units", "units_for"]


def check_units(units: Any, channels: tuple[str, ...]) -> tuple[str, ...] | None:
    """``units`` as a tuple of strings, one per channel (``None``: no units recorded)."""
    if units is None:
        return None
    if (
        not isinstance(units, Sequence)
        or isinstance(units, str | bytes)
        or not all(isinstance(u, str) for u in units)
    ):
        raise ValueError(
            f"Episode units={units!r} is outside the allowed range: a sequence of unit strings, "
            f"one per channel ('' for an unknown unit), e.g. ('°C', 't/h'), or None"
        )
    if len(units) != len(channels):
        raise ValueError(
            f"Episode units has {len(units)} entries {list(units)} for {len(channels)} channels "
            f"{list(channels)}; allowed: one unit per channel ('' for an unknown unit)"
        )
    return tuple(units)


def units_for(
    channels: Sequence[str], known: Mapping[str, Any] | None, where: str = "units"
) -> tuple[str, ...] | None:
    """The unit of each of ``channels`` from ``known`` (``{column: unit}``), ``""`` where it has
    none; ``None`` when ``known`` knows none of them (nothing was recorded)."""
    if not known:
        return None
    out = []
    for c in channels:
        u = known.get(c)
        if u is not None and not isinstance(u, str):
            raise ValueError(
                f"{where}: the unit of column {c!r} is {u!r}; allowed: a string such as '°C' "
                "(or no entry for an unknown unit)"
            )
        out.append((u or "").strip())
    return tuple(out) if any(out) else None


def sidecar_units(
    meta: Mapping[str, Any], channels: Sequence[str], where: str
) -> tuple[str, ...] | None:
    """The units of ``channels`` from a dataset sidecar's ``columns[name]["unit"]``."""
    columns = meta.get("columns")
    if columns is None:
        return None
    if not isinstance(columns, Mapping) or not all(
        isinstance(v, Mapping) for v in columns.values()
    ):
        raise ValueError(
            f"{where}: 'columns' must map column names to objects with a 'unit', got "
            f"{type(columns).__name__}"
        )
    return units_for(channels, {c: v.get("unit") for c, v in columns.items()}, f"{where} columns")

"""One definition of each environment's ``info`` entries, read for the whole batch or for one row.

A core lists its entries as ``InfoField``s: a name, how to read the (N, ...) batch values from the
core's arrays, and the Python type of a single row's value (``None``: an array). ``info_batch`` and
``info_row`` both come from that one list, so the single env, the vector env and the SB3 adapter
report the same entries with the same values.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class InfoField:
    """An ``info`` entry: ``read(core)`` returns its (N, ...) values; ``scalar`` converts one row's value."""

    name: str
    read: Callable[[Any], np.ndarray]
    scalar: type | None = float
    doc: str = ""


def column(attribute: str, index: int, kind: type = float) -> Callable[[Any], np.ndarray]:
    """Reader of column ``index`` of the core's array ``attribute`` (as ``kind``: float or bool)."""
    if kind is bool:
        return lambda core: getattr(core, attribute)[:, index] != 0
    return lambda core: getattr(core, attribute)[:, index]


def bits(attribute: str, index: int) -> Callable[[Any], np.ndarray]:
    """Reader of a per-joint bit mask stored in column ``index`` of ``attribute``: (N, dof) bools."""
    def read(core) -> np.ndarray:
        values = getattr(core, attribute)[:, index]
        return ((values[:, None] >> np.arange(core.dof)) & 1).astype(bool)

    return read


def attribute(name: str) -> Callable[[Any], np.ndarray]:
    """Reader of a per-row array attribute of the core (e.g. ``gamma``, ``base_cmd``)."""
    return lambda core: getattr(core, name)


def info_batch(fields: Sequence[InfoField], core) -> dict:
    """{name: (N, ...) array} of every field (fresh arrays, never views of the core's state)."""
    return {f.name: np.array(f.read(core)) for f in fields}


def info_row(fields: Sequence[InfoField], core, row: int) -> dict:
    """{name: value} of one row: Python scalars for scalar fields, fresh arrays for the others."""
    out = {}
    for f in fields:
        value = f.read(core)[row]
        out[f.name] = value.copy() if f.scalar is None else f.scalar(value)
    return out


def fields_table(fields: Sequence[InfoField]) -> str:
    """Markdown list of the entries and their meaning (for the env docstrings)."""
    return "\n".join(f"    - ``{f.name}``: {f.doc}" for f in fields)

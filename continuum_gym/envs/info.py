"""One definition of each environment's ``info`` entries, read for the whole batch or for one row.

A core lists its entries as ``InfoField``s: a name, how to read the (N, ...) batch values from the
core's arrays, and the Python type of a single row's value (``None``: an array). ``info_batch`` and
``info_row`` both come from that one list, so the single env, the vector env and the SB3 adapter
report the same entries with the same values: numpy arrays (batch) and numpy scalars (one row), and
the weighted reward terms as one named array ``reward_terms`` (``RewardTerms``).
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
    #: (N, ...) values; a reader with ``attribute`` and ``pick(source_row, core)`` also reads one row
    #: from the row of its source array (shared with the other fields of that array)
    read: Callable[[Any], np.ndarray]
    scalar: type | None = float
    doc: str = ""


class Column:
    """Reader of column ``index`` of the core's (N, k) array ``attribute`` (as ``kind``: float or bool)."""

    def __init__(self, attribute: str, index: int, kind: type = float) -> None:
        self.attribute, self.index, self.kind = attribute, index, kind

    def __call__(self, core) -> np.ndarray:
        values = getattr(core, self.attribute)[:, self.index]
        return values != 0 if self.kind is bool else values

    def pick(self, values: np.ndarray, core) -> Any:
        """This field's value from one row of the source array (``values = source[row]``)."""
        value = values[self.index]
        return value != 0 if self.kind is bool else value


class Bits:
    """Reader of a per-joint bit mask stored in column ``index`` of ``attribute``: (N, dof) bools."""

    def __init__(self, attribute: str, index: int) -> None:
        self.attribute, self.index = attribute, index

    def __call__(self, core) -> np.ndarray:
        values = getattr(core, self.attribute)[:, self.index]
        return ((values[:, None] >> np.arange(core.dof)) & 1).astype(bool)

    def pick(self, values: np.ndarray, core) -> np.ndarray:
        mask = int(values[self.index])
        dof = core.dof
        table = _BIT_TABLES.get(dof)
        if table is None:  # every mask of dof bits, unpacked once: a row's read is then one copy
            table = _BIT_TABLES[dof] = ((np.arange(1 << dof)[:, None] >> np.arange(dof)) & 1).astype(bool)
        return table[mask].copy()


_BIT_TABLES: dict[int, np.ndarray] = {}


class Attribute:
    """Reader of a per-row array of the core, by a dotted path (``gamma``, ``base_cmd``, ``tasks.task_id``)."""

    def __init__(self, path: str) -> None:
        self.path = path.split(".")

    def __call__(self, core) -> np.ndarray:
        value = core
        for part in self.path:
            value = getattr(value, part)
        return value

    @property
    def attribute(self) -> str:
        return ".".join(self.path)

    def pick(self, values: Any, core) -> Any:
        return values


class AtMost:
    """Reader of ``attribute[:, index] <= bound`` (bools)."""

    def __init__(self, attribute: str, index: int, bound: float) -> None:
        self.attribute, self.index, self.bound = attribute, index, bound

    def __call__(self, core) -> np.ndarray:
        return getattr(core, self.attribute)[:, self.index] <= self.bound

    def pick(self, values: np.ndarray, core) -> Any:
        return values[self.index] <= self.bound


def column(attribute: str, index: int, kind: type = float) -> Column:
    """Reader of column ``index`` of the core's array ``attribute`` (as ``kind``: float or bool)."""
    return Column(attribute, index, kind)


def bits(attribute: str, index: int) -> Bits:
    """Reader of a per-joint bit mask stored in column ``index`` of ``attribute``: (N, dof) bools."""
    return Bits(attribute, index)


def attribute(name: str) -> Attribute:
    """Reader of a per-row array attribute of the core (e.g. ``gamma``, ``base_cmd``, ``tasks.task_id``)."""
    return Attribute(name)


def info_batch(fields: Sequence[InfoField], core) -> dict:
    """{name: (N, ...) array} of every field (fresh arrays, never views of the core's state)."""
    return {f.name: np.array(f.read(core)) for f in fields}


#: A single row's value of each scalar kind: numpy scalars (with a dtype, like the vector env's arrays),
#: so that clients that read infos as arrays (torchrl, Gymnasium's vector wrappers) take them as they are.
NUMPY_SCALARS = {float: np.float64, bool: np.bool_, int: np.int64}


def info_row(fields: Sequence[InfoField], core, row: int) -> dict:
    """{name: value} of one row: numpy scalars for scalar fields, fresh arrays for the others."""
    out = {}
    rows = {}  # each source array's row, read once for all the fields that come from it
    for name, source, pick, kind in _row_plan(fields):
        if source is None:  # a reader without ``pick``: the whole batch, indexed
            value = pick(core)[row]
        else:
            values = rows.get(source)
            if values is None:
                values = rows[source] = _read_source(core, source)[row]
            value = pick(values, core)
        if kind is None:
            out[name] = np.array(value)
        else:  # most reads already give the numpy scalar (float64 columns, int64 counters): no conversion
            out[name] = value if type(value) is kind else kind(value)
    return out


def _read_source(core, source: str) -> Any:
    value = core
    for part in source.split("."):
        value = getattr(value, part)
    return value


_ROW_PLANS: dict[int, tuple] = {}


def _row_plan(fields: Sequence[InfoField]) -> tuple:
    """(name, source array, pick from its row, numpy scalar type or None) per field, worked out once.

    The single env builds ``info`` every step, where looking readers up and reading each field's
    array separately cost more than the values themselves. A reader without ``pick`` reads the
    whole batch and indexes the row.
    """
    plan = _ROW_PLANS.get(id(fields))
    if plan is None or plan[0] is not fields:
        entries = []
        for f in fields:
            kind = None if f.scalar is None else NUMPY_SCALARS[f.scalar]
            if hasattr(f.read, "pick"):
                entries.append((f.name, f.read.attribute, f.read.pick, kind))
            else:
                entries.append((f.name, None, f.read, kind))
        plan = _ROW_PLANS[id(fields)] = (fields, tuple(entries))
    return plan[1]


def fields_table(fields: Sequence[InfoField]) -> str:
    """Markdown list of the entries and their meaning (for the env docstrings)."""
    return "\n".join(f"    - ``{f.name}``: {f.doc}" for f in fields)


class RewardTerms(np.ndarray):
    """The weighted reward terms of a step: a float64 array that also reads like a ``{term: value}`` dict.

    ``info["reward_terms"]["voi"]`` is the weighted VOI term (a numpy scalar for one env, an (N,) array
    for a vector env), ``keys()`` / ``values()`` / ``items()`` / ``in`` / iteration behave as on a dict
    keyed by term name, and ``sum(terms.values())`` is the step's reward. It stays a plain numeric array
    (shape (n_terms,) or (N, n_terms), columns in ``names`` order), so clients that turn every info entry
    into a tensor (torchrl's info readers) take it as it is; a nested dict would break them.
    """

    names: tuple[str, ...]

    def __new__(cls, values: np.ndarray, names: Sequence[str]) -> RewardTerms:
        terms = np.array(values, dtype=np.float64).view(cls)
        if terms.shape[-1:] != (len(names),):
            raise ValueError(f"reward terms: last axis must have {len(names)} entries (names {tuple(names)}); "
                             f"got shape {terms.shape}")
        terms.names = tuple(names)
        return terms

    @classmethod
    def of_checked(cls, values: np.ndarray, names: tuple[str, ...]) -> RewardTerms:
        """A copy of float64 ``values`` whose last axis is already known to match ``names`` (a core's own rows)."""
        terms = values.copy().view(cls)
        terms.names = names
        return terms

    def __array_finalize__(self, source) -> None:
        self.names = getattr(source, "names", ())

    def __reduce__(self):  # pickles (async vector envs, checkpoints) with its names
        return RewardTerms, (self.view(np.ndarray), self.names)

    def _column(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no reward term {name!r}; the terms are {self.names}") from None

    def __getitem__(self, key):
        if isinstance(key, str):
            return self.view(np.ndarray)[..., self._column(key)]
        if self.ndim == 2 and isinstance(key, (int, np.integer)):  # one env's terms of a batch, still named
            return RewardTerms(self.view(np.ndarray)[key], self.names)
        return self.view(np.ndarray)[key]

    def __contains__(self, key) -> bool:
        return key in self.names if isinstance(key, str) else bool(np.ndarray.__contains__(self, key))

    def __iter__(self):
        return iter(self.names)

    def keys(self) -> tuple[str, ...]:
        return self.names

    def values(self) -> list:
        return [self[name] for name in self.names]

    def items(self) -> list:
        return [(name, self[name]) for name in self.names]

    def get(self, name: str, default: Any = None) -> Any:
        return self[name] if name in self.names else default

    def as_dict(self) -> dict:
        """A plain ``{term: value}`` dict (e.g. for JSON)."""
        return dict(self.items())

"""One definition of each environment's ``info`` entries, read for the whole batch or for one row.

A core lists its entries as ``InfoField``s: a name, how to read the (N, ...) batch values from the
core's arrays, and the Python type of a single row's value (``None``: an array). ``info_batch`` and
``row_reader`` (behind a core's ``info`` / ``info_row``) both come from that one list, so the single
env, the vector env and the SB3 adapter report the same entries with the same values: numpy arrays
(batch) and numpy scalars (one row), and the weighted reward terms as one named array
``reward_terms`` (``RewardTerms``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass
from typing import Any, cast

import numpy as np


@dataclass(frozen=True)
class InfoField:
    """An ``info`` entry: ``read(core)`` returns its (N, ...) values; ``scalar`` converts one row's value."""

    name: str
    #: (N, ...) values; a reader with ``attribute``, ``expression(row_name)`` and ``batch_expression(name)``
    #: also reads one row (or the batch) through generated code, from its source array read once for
    #: all the fields of that array
    read: Callable[[Any], np.ndarray]
    scalar: type | None = float
    doc: str = ""


class Column:
    """Reader of column ``index`` of the core's (N, k) array ``attribute`` (as ``kind``: float or bool)."""

    def __init__(self, attribute: str, index: int, kind: type = float) -> None:
        self.attribute, self.index, self.kind = attribute, int(index), kind

    def __call__(self, core) -> np.ndarray:
        values = getattr(core, self.attribute)[:, self.index]
        return values != 0 if self.kind is bool else values

    def expression(self, row: str) -> str:
        """Python expression of this field's value, given the name of one row of the source array."""
        return f"({row}[{self.index}] != 0)" if self.kind is bool else f"{row}[{self.index}]"

    def batch_expression(self, source: str) -> str:
        """Python expression of the (N, ...) values as a fresh array, given the name of the source array."""
        return f"({source}[:, {self.index}] != 0)" if self.kind is bool else f"{source}[:, {self.index}].copy()"


class Bits:
    """Reader of a per-joint bit mask stored in column ``index`` of ``attribute``: (N, dof) bools."""

    def __init__(self, attribute: str, index: int) -> None:
        self.attribute, self.index = attribute, int(index)

    def __call__(self, core) -> np.ndarray:
        return _bits_of(getattr(core, self.attribute)[:, self.index], core.dof)

    fresh = True  # its row value is a new array already

    def expression(self, row: str) -> str:
        return f"bit_rows[{row}[{self.index}] & bit_mask].copy()"

    def batch_expression(self, source: str) -> str:
        return f"_bits({source}[:, {self.index}], core.dof)"


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

    def expression(self, row: str) -> str:
        return row

    def batch_expression(self, source: str) -> str:
        return f"{source}.copy()"


class AtMost:
    """Reader of ``attribute[:, index] <= bound`` (bools)."""

    def __init__(self, attribute: str, index: int, bound: float) -> None:
        self.attribute, self.index, self.bound = attribute, int(index), bound

    def __call__(self, core) -> np.ndarray:
        return getattr(core, self.attribute)[:, self.index] <= self.bound

    def expression(self, row: str) -> str:
        return f"({row}[{self.index}] <= {float(self.bound)!r})"

    def batch_expression(self, source: str) -> str:
        return f"({source}[:, {self.index}] <= {float(self.bound)!r})"


def column(attribute: str, index: int, kind: type = float) -> Column:
    """Reader of column ``index`` of the core's array ``attribute`` (as ``kind``: float or bool)."""
    return Column(attribute, index, kind)


def bits(attribute: str, index: int) -> Bits:
    """Reader of a per-joint bit mask stored in column ``index`` of ``attribute``: (N, dof) bools."""
    return Bits(attribute, index)


def attribute(name: str) -> Attribute:
    """Reader of a per-row array attribute of the core (e.g. ``gamma``, ``base_cmd``, ``tasks.task_id``)."""
    return Attribute(name)


def info_batch(fields: Sequence[InfoField], core: Any) -> dict:  # core: a BatchedCore (read by attribute name)
    """{name: (N, ...) array} of every field (fresh arrays, never views of the core's state)."""
    key = (id(fields), "batch")
    cached = _READERS.get(key)
    if cached is None or cached[0] is not fields:
        cached = _READERS[key] = (fields, _write_reader(fields, batch=True))
    return cached[1](core)


#: A single row's value of each scalar kind: numpy scalars (with a dtype, like the vector env's arrays),
#: so that clients that read infos as arrays (torchrl, Gymnasium's vector wrappers) take them as they are.
NUMPY_SCALARS = {float: np.float64, bool: np.bool_, int: np.int64}


#: (id of a field list, "row" / "batch") -> (the field list, its written-out reader)
_READERS: dict[tuple[int, str], tuple] = {}


def row_reader(fields: Sequence[InfoField], core: Any) -> Callable:  # core: as in info_batch
    """A function ``(core, row) -> info dict`` written out for ``fields``, made once per field list.

    The single env builds ``info`` every step (and the vector env its batch version, ``info_batch``);
    a loop over the fields that resolves each reader costs more than the values themselves (15 fields:
    ~8 us against ~2 us for the dict written out, the way ``dataclasses`` writes ``__init__``), and for
    small batches more than the kernel. Each source array (or its row) is read once. Readers with
    ``expression`` / ``batch_expression`` say how their value is read from it; others are called on the
    whole batch. A row value whose type is not the field's numpy scalar type on the first call gets a
    conversion.
    """
    key = (id(fields), "row")
    cached = _READERS.get(key)
    if cached is not None and cached[0] is fields:
        return cached[1]
    reader = _write_reader(fields, batch=False)
    sample = reader(core, 0)
    convert = {f.name for f in fields if f.scalar is not None and type(sample[f.name]) is not NUMPY_SCALARS[f.scalar]}
    if convert:
        reader = _write_reader(fields, batch=False, convert=convert)
    _READERS[key] = (fields, reader)
    return reader


def _write_reader(fields: Sequence[InfoField], batch: bool, convert: AbstractSet[str] = frozenset()) -> Callable:
    """``info_batch(core)`` (``batch``) or ``info_row(core, row)`` for ``fields``, as compiled Python."""
    namespace: dict[str, Any] = {"_array": np.array, "_bits": _bits_of, "_bit_table": _bit_table}
    index = "" if batch else "[row]"
    sources: dict[str, str] = {}
    lines = []
    if not batch and any(isinstance(f.read, Bits) for f in fields):  # one row of the table per bit field
        lines.append("    bit_rows = _bit_table(core.dof)")
        lines.append("    bit_mask = (1 << core.dof) - 1")
    entries = []
    for k, f in enumerate(fields):
        read: Any = f.read  # a reader with expression / batch_expression, or any callable
        written = hasattr(read, "expression")
        if written:
            source = sources.get(read.attribute)
            if source is None:
                source = sources[read.attribute] = f"s{len(sources)}"
                lines.append(f"    {source} = core.{read.attribute}{index}")
            expression = read.batch_expression(source) if batch else read.expression(source)
        else:
            namespace[f"_read{k}"] = read
            expression = f"_read{k}(core){index}"
        if batch:  # batch expressions give fresh arrays; a plain reader's result is copied
            expression = expression if written else f"_array({expression})"
        elif f.scalar is None and not getattr(read, "fresh", False):
            expression = f"_array({expression})"
        elif f.name in convert:
            namespace[f"_kind{k}"] = NUMPY_SCALARS[cast(type, f.scalar)]  # convert holds fields with a scalar
            expression = f"_kind{k}({expression})"
        entries.append(f"        {f.name!r}: {expression},")
    name = "info_batch" if batch else "info_row"
    source = "\n".join([f"def {name}(core{'' if batch else ', row'}):", *lines, "    return {", *entries, "    }"])
    exec(compile(source, f"<continuum_gym {name}>", "exec"), namespace)  # noqa: S102 - our own field list
    return namespace[name]


def _bit_table(dof: int) -> np.ndarray:
    """Every mask of ``dof`` bits, unpacked once ((2^dof, dof) bools): a read is then one lookup."""
    table = _BIT_TABLES.get(dof)
    if table is None:
        table = _BIT_TABLES[dof] = ((np.arange(1 << dof)[:, None] >> np.arange(dof)) & 1).astype(bool)
    return table


def _bits_of(masks, dof: int) -> np.ndarray:
    """The (N, dof) bools of an (N,) array of joint bit masks (fresh; bits above the dof-th are ignored)."""
    return _bit_table(dof)[np.bitwise_and(masks, (1 << dof) - 1)]  # fancy indexing copies


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

    __slots__ = ("names",)  # no instance __dict__: made every step of a single env
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


"""The columns of a step kernel's arrays, declared once: the kernels' constants and the docs' tables.

A kernel writes rows of a few arrays whose columns mean something: the observation, the ``metrics`` and
the ``flags``. Each is declared here once, with what each column holds, and both the compiled code and
the documentation are made from that declaration, so the two cannot drift apart:

* :class:`Columns`, for arrays with a fixed set of named columns (``metrics``, ``flags``): an ``IntEnum``
  whose members are the column indices (numba compiles ``metrics[i, Metric.VOI]`` to a constant index,
  as it would ``metrics[i, 0]``) and carry their description; ``table()`` is the docs' table.
* :class:`Layout`, for an observation made of consecutive blocks whose lengths may grow with the robot's
  number of segments: ``offsets()`` is a namedtuple of each block's start as ``(per_segment, constant)``
  (read in a kernel with :func:`at`; ``starts()``: plain ints when no block grows), ``width(n)`` the
  observation's length, and ``table(n)`` the env docstring's ``| Num | Observation | Scale |`` table for ``n`` segments.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass
from enum import IntEnum
from typing import Any


@dataclass(frozen=True)
class Episode:
    """A per-episode value the evaluation reduces from a column, and the table column it may fill."""

    name: str  #: key of the per-episode results and the JSON (``mean_voi``)
    reduce: str = "mean"  #: "mean" over the episode's steps, or "final" (the last step's value)
    label: str = ""  #: words of a table column and figure axis; "" : a diagnostic value, not a column
    higher_is_better: bool = False
    unit: str = ""  #: SI unit of the value ("" for ratios, "%" for percentages)
    display_unit: str = ""  #: unit shown in tables and figures ("" = ``unit``)
    display_scale: float = 1.0  #: value x scale = shown value
    #: a coverage column: 100 x the fraction of the grid's episodes whose ``final`` value exceeds this
    grid_threshold: float | None = None


def mean(name: str, label: str = "", *, higher_is_better: bool = False, unit: str = "", display_unit: str = "",
         display_scale: float = 1.0) -> Episode:
    """The episode's mean of a column (a table column when ``label`` is given)."""
    return Episode(name, "mean", label, higher_is_better, unit, display_unit, display_scale)


@dataclass(frozen=True)
class Value:
    """What a column of ``metrics`` or ``flags`` holds, declared once: the kernel writes it (``Metric.VOI`` is
    its index), and from this declaration it reaches ``info``, the env docstring and the evaluation's tables."""

    doc: str
    info: str = ""  #: its ``info`` entry ("" : none)
    kind: str = "float"  #: the ``info`` value: "float", "bool" (the column is 0 or 1), "bits" (per joint, (dof,))
    unit: str = ""  #: SI unit ("" for ratios and flags)
    episode: tuple[Episode, ...] = ()  #: what the evaluation reduces from it per episode


#: Every env's last flag, which the library sets (``envs/rows.py``) and reads (``envs/faults.py``).
NON_FINITE = Value("a value of the row was not finite (NaN or inf) and its episode ended as truncated (only with "
                   "``on_non_finite='truncate'``; its metrics are NaN)", info="non_finite", kind="bool")


class Columns(IntEnum):
    """Named columns of an array, in declaration order: declare each as ``NAME = "what it holds"`` or
    ``NAME = Value(...)`` (a value that reaches ``info`` and the evaluation).

    A member is the column's index (an ``int``, usable in numpy and in compiled kernels) and carries its
    declaration as ``declared`` and its description as ``doc``.
    """

    doc: str
    declared: Value

    def __new__(cls, declared: str | Value) -> Columns:
        index = len(cls.__members__)
        member = int.__new__(cls, index)
        member._value_ = index
        member.declared = declared if isinstance(declared, Value) else Value(declared)
        member.doc = member.declared.doc
        return member

    @classmethod
    def table(cls, prefix: str = "") -> str:
        """The declared columns as a markdown list ``index: `NAME` - doc``, one per line."""
        return "\n".join(f"- {int(c)}: `{prefix}{c.name}` - {c.doc}" for c in cls)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The members' names in column order."""
        return tuple(c.name for c in cls)


@dataclass(frozen=True)
class Block:
    """Consecutive observation entries: ``size + per_segment * n`` of them for a robot of n segments."""

    name: str
    what: str
    scale: str
    size: int = 1
    per_segment: int = 0

    def length(self, n_segments: int) -> int:
        return self.size + self.per_segment * n_segments


class Layout:
    """An observation row as consecutive :class:`Block`s (names are Python identifiers, unique)."""

    def __init__(self, name: str, *blocks: Block) -> None:
        names = [b.name for b in blocks]
        if len(set(names)) != len(names) or not all(n.isidentifier() for n in names):
            raise ValueError(f"{name}: block names must be unique identifiers; got {names}")
        self.name = name
        self.blocks = blocks

    def offsets(self) -> Any:  # a namedtuple class made at run time: typed as Any
        """Each block's start as ``(per_segment, constant)``: entry ``per_segment * n + constant``."""
        per, const = 0, 0
        starts = {}
        for b in self.blocks:
            starts[b.name] = (per, const)
            per, const = per + b.per_segment, const + b.size
        return namedtuple(self.name, list(starts))(**starts)

    def starts(self) -> Any:
        """Each block's first entry (an int) of a layout whose blocks do not grow with the robot."""
        if any(b.per_segment for b in self.blocks):
            raise ValueError(f"{self.name}: its blocks grow with the robot's segments; use offsets() and at()")
        return namedtuple(self.name, [b.name for b in self.blocks])(*(c for _, c in self.offsets()))

    def width(self, n_segments: int = 0, upto: str | None = None) -> int:
        """Entries of a row (of the blocks before ``upto`` when given) for a robot of ``n_segments``."""
        total = 0
        for b in self.blocks:
            if b.name == upto:
                return total
            total += b.length(n_segments)
        if upto is not None:
            raise ValueError(f"upto: {upto!r} is not a block of {self.name} ({[b.name for b in self.blocks]})")
        return total

    def table(self, n_segments: int = 0, indent: str = "    ") -> str:
        """The markdown table ``| Num | Observation | Scale |`` of a robot of ``n_segments``."""
        lines = ["| Num | Observation | Scale |", "|-----|-------------|-------|"]
        start = 0
        for b in self.blocks:
            stop = start + b.length(n_segments) - 1
            num = str(start) if stop == start else f"{start}-{stop}"
            lines.append(f"| {num} | {b.what} | {b.scale} |")
            start = stop + 1
        return "\n".join(indent + line for line in lines)


def at(block_start: tuple[int, int], n_segments: int) -> int:
    """Index of a :class:`Layout` block's first entry (``offsets()``'s ``(per_segment, constant)``) for
    a robot of ``n_segments``: plain Python; the kernels use ``common_kernels.at``, its compiled twin."""
    return block_start[0] * n_segments + block_start[1]

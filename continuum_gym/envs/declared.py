"""What an environment's declared columns give the rest of the library: ``info``, step values, table columns.

A column of ``metrics`` or ``flags`` declared as a ``Value`` (``envs/columns.py``) is written by the env's row
function; from that one declaration this module makes its ``info`` entry (``info_fields``), the per-step value
the evaluation reduces (``step_values``), its per-episode reductions (``episode_metrics``) and the evaluation's
table columns (``table_metrics``). No env lists any of these a second time.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from continuum_gym.envs.columns import Columns, Episode
from continuum_gym.envs.info import InfoField, attribute, bits, column


@dataclass(frozen=True)
class Metric:
    """A column of the evaluation table (made from a declared column's ``Episode``)."""

    name: str  #: key in the per-episode results and the JSON
    label: str  #: words for tables and figure axes
    unit: str  #: SI unit of the stored value ("" for ratios, "%" for percentages)
    higher_is_better: bool
    display_unit: str = ""  #: unit shown in tables and figures ("" = ``unit``)
    display_scale: float = 1.0  #: stored value x scale = shown value
    grid_metric: str = ""  #: if set: 100 x the fraction of grid episodes whose ``grid_metric`` > ``threshold``
    threshold: float = 0.0

    def axis_label(self) -> str:
        """'<label> (<unit>), lower is better' for figure axes."""
        unit = self.display_unit or self.unit
        direction = "higher is better" if self.higher_is_better else "lower is better"
        return f"{self.label}{f' ({unit})' if unit else ''}, {direction}"


@dataclass(frozen=True)
class EpisodeMetric:
    """How a per-episode metric is reduced from the per-step values of ``core.step_values()``."""

    name: str
    step_value: str
    reduce: str = "mean"  #: "mean" over the episode's steps, or "final" (the last step's value)


#: The library's own ``info`` entries of every env, after the declared columns and the env's own.
LIBRARY_INFO = (
    InfoField("base_command", attribute("base_cmd"), None,
              "the baseline's command at the new state (the action's layout; rad/s, m/s)"),
    InfoField("task_id", attribute("tasks.task_id"), int, "task instance"),
    InfoField("elapsed_steps", attribute("steps"), int, "control steps since reset"),
)
#: The arrays a declaration of each enum class lives in.
_ARRAYS = {"Metric": "metrics", "Flag": "flags"}
_CACHE: dict[int, tuple] = {}


def array_of(columns: type[Columns]) -> str:
    """``metrics`` or ``flags``: the array whose columns ``columns`` (an env's ``Metric`` or ``Flag``) declares."""
    try:
        return _ARRAYS[columns.__name__]
    except KeyError:
        raise ValueError(f"declared columns must be named Metric or Flag (the arrays metrics and flags); got "
                         f"{columns.__name__}") from None


def info_fields(declared: Iterable[type[Columns]], extra: Iterable[InfoField] = ()) -> tuple[InfoField, ...]:
    """The ``info`` entries of the declared columns (with ``info`` names), then ``extra``, then the library's.

    The same tuple for the same declarations (the info readers are written once per tuple, ``envs/info.py``).
    """
    declared, extra = tuple(declared), tuple(extra)
    key = hash((declared, extra))
    cached = _CACHE.get(key)
    if cached is not None and cached[0] == (declared, extra):
        return cached[1]
    fields = []
    for columns in declared:
        array = array_of(columns)
        for c in columns:
            value = c.declared
            if not value.info:
                continue
            if value.kind == "bits":
                fields.append(InfoField(value.info, bits(array, c), None, value.doc))
            elif value.kind == "bool":
                fields.append(InfoField(value.info, column(array, c, bool), bool, value.doc))
            else:
                fields.append(InfoField(value.info, column(array, c), float, value.doc))
    result = (*fields, *extra, *LIBRARY_INFO)
    _CACHE[key] = ((declared, extra), result)
    return result


def reduced(declared: Iterable[type[Columns]]) -> list[tuple[Any, Episode]]:
    """Every (column, episode reduction) the declarations hold, in declaration order."""
    return [(c, episode) for columns in declared for c in columns for episode in c.declared.episode]


def step_values(core: Any, declared: Iterable[type[Columns]]) -> dict[str, np.ndarray]:
    """{info name: (N,) values} of the declared columns the evaluation reduces (flags as 0.0 / 1.0)."""
    out: dict[str, np.ndarray] = {}
    for columns in declared:
        array = getattr(core, array_of(columns))
        for c in columns:
            if c.declared.episode:
                values = array[:, c]
                out[c.declared.info or c.name.lower()] = values if array.dtype.kind == "f" else (values != 0) * 1.0
    return out


def episode_metrics(declared: Iterable[type[Columns]]) -> tuple:
    """The ``EpisodeMetric``s of the declarations (coverage columns are computed from a ``final`` value)."""
    return tuple(EpisodeMetric(episode.name, c.declared.info or c.name.lower(), episode.reduce)
                 for c, episode in reduced(declared) if episode.grid_threshold is None)


def table_metrics(declared: Iterable[type[Columns]], names: Iterable[str]) -> tuple:
    """The evaluation's table columns ``names`` (``spec.Metric``), in that order, from the declarations."""
    declared = tuple(declared)
    found = {}
    for c, episode in reduced(declared):
        grid = ""
        if episode.grid_threshold is not None:
            grid = next((e.name for e in c.declared.episode if e.reduce == "final" and e.grid_threshold is None), "")
            if not grid:
                raise ValueError(f"{c.name}: the coverage column {episode.name!r} needs a 'final' episode value of "
                                 "the same column")
        found[episode.name] = Metric(episode.name, episode.label, episode.unit, episode.higher_is_better,
                                     episode.display_unit, episode.display_scale, grid, episode.grid_threshold or 0.0)
    missing = [name for name in names if name not in found or not found[name].label]
    if missing:
        raise ValueError(f"metrics {missing} are not declared as labelled episode values of the columns "
                         f"(declared: {sorted(n for n, m in found.items() if m.label)})")
    return tuple(found[name] for name in names)


__all__ = ["Metric", "EpisodeMetric", "info_fields", "step_values", "episode_metrics", "table_metrics", "LIBRARY_INFO", "array_of"]

"""Ratios between two trees' benchmark results: keys, units, best-of, noise, the table and the JSON.

Used by ``compare.py`` and ``paired.py``; ``compare.py``'s docstring says how units and directions are read.
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

FLAG_BELOW = 0.95

#: direction of a unit: +1 higher is better, -1 lower is better, 0 no direction (shown, not judged)
HIGHER, LOWER, NONE = 1, -1, 0


@dataclass
class Run:
    """One finished benchmark run and how busy the rest of the machine was meanwhile."""

    script: str
    tree: str
    seconds: float
    load_before: float  # 1-min load average
    others_before: float  # cores used by other processes just before (1 s sample)
    others_during: float  # mean cores used by other processes during the run
    results: dict[str, Any]
    busy: bool = False  # others used more than --idle-below cores during it (set by the caller)


# ---------------------------------------------------------------------------------------------- keys
def flatten(results: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """{dotted key: leaf} of a nested JSON object."""
    flat: dict[str, Any] = {}
    for key, value in results.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def numeric(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def unit_of(key: str, units: dict[str, str], rate_default: bool) -> str:
    """Unit of a flattened key: the first matching ``units`` pattern, else a guess from its name."""
    if key in units:
        return units[key]
    for pattern, unit in units.items():
        if fnmatch.fnmatchcase(key, pattern):
            return unit
    leaf = key.rsplit(".", 1)[-1]
    if key.startswith(("machine.", "load_average")) or leaf in ("cpus", "bodies"):
        return "info"
    if leaf == "ratio":
        return "x (derived)"
    if leaf.endswith(("per_second", "per_cpu_second")):
        return "1/s"
    if leaf.endswith("_us") or leaf == "microseconds":
        return "us"
    if leaf.endswith(("milliseconds", "_ms")):
        return "ms"
    if leaf.endswith("_s") or leaf == "seconds":
        return "s"
    if leaf.endswith("_mib") or key.startswith("memory."):
        return "MiB"
    if "." not in key and rate_default:
        return "1/s"
    return "?"


def direction(unit: str) -> int:
    """+1 if more of ``unit`` is better, -1 if less is, 0 for derived, control-free unknowns and info."""
    if "(derived)" in unit or unit in ("info", "?"):
        return NONE
    base = unit.split(" (")[0]
    if base.endswith("/s"):
        return HIGHER
    if base in ("us", "ms", "s", "MiB"):
        return LOWER
    return HIGHER if base == "x" else NONE


def best(values: list[float], sense: int) -> float:
    """The run least disturbed by other processes: max of a rate, min of a time; median without a sense."""
    if sense == HIGHER:
        return max(values)
    if sense == LOWER:
        return min(values)
    return statistics.median(values)


def spread(values: list[float], sense: int) -> float:
    """(worst - best) / best over the repeats, as a fraction; 0 for one run or no direction."""
    if len(values) < 2 or sense == NONE:
        return 0.0
    top = best(values, sense)
    worst = min(values) if sense == HIGHER else max(values)
    return abs(top - worst) / abs(top) if top else 0.0


@dataclass
class Row:
    """One compared key."""

    key: str
    unit: str
    sense: int
    old: list[float] = field(default_factory=list)
    new: list[float] = field(default_factory=list)

    @property
    def old_best(self) -> float | None:
        return best(self.old, self.sense) if self.old else None

    @property
    def new_best(self) -> float | None:
        return best(self.new, self.sense) if self.new else None

    @property
    def speed(self) -> float | None:
        """> 1: the new tree is better (new/old of a rate, old/new of a time or memory)."""
        old, new = self.old_best, self.new_best
        if old is None or new is None or old <= 0 or new <= 0:
            return None
        return old / new if self.sense == LOWER else new / old

    @property
    def noise(self) -> float:
        return max(spread(self.old, self.sense), spread(self.new, self.sense))

    @property
    def flagged(self) -> bool:
        return self.sense != NONE and "(control)" not in self.unit and self.speed is not None \
            and self.speed < FLAG_BELOW

    def as_json(self) -> dict:
        return {"key": self.key, "unit": self.unit,
                "better": {HIGHER: "higher", LOWER: "lower", NONE: None}[self.sense],
                "old": self.old_best, "new": self.new_best, "speed_new_vs_old": self.speed,
                "noise": self.noise, "flagged": self.flagged, "old_runs": self.old, "new_runs": self.new}


def usable(runs: list[Run]) -> list[Run]:
    """Per tree, the runs the rest of the machine left alone if there are any, else all of them."""
    kept: list[Run] = []
    for label in ("old", "new"):
        mine = [r for r in runs if r.tree == label]
        kept += [r for r in mine if not r.busy] or mine
    return kept


def compare_runs(runs: list[Run]) -> list[Row]:
    """Rows of every numeric key seen in either tree's runs of one script, in first-seen order.

    ``runs`` should already be ``usable(...)``: a busy run can only lower a best-of, but it widens the
    noise column and moves the median of the rows without a direction.
    """
    units: dict[str, str] = {}
    rate_default = False
    # The newest script's explicit units win; an old script without them falls back to the same map,
    # since the rows are matched by key.
    for run in sorted(runs, key=lambda r: r.tree != "new"):
        for pattern, unit in (run.results.get("units") or {}).items():
            units.setdefault(pattern, unit)
        rate_default |= "per second" in str(run.results.get("unit", ""))
    rows: dict[str, Row] = {}
    for run in runs:
        for key, value in flatten({k: v for k, v in run.results.items() if k not in ("units", "source")}).items():
            if not numeric(value):
                continue
            unit = unit_of(key, units, rate_default)
            if unit == "info":
                continue
            row = rows.setdefault(key, Row(key, unit, direction(unit)))
            getattr(row, run.tree).append(float(value))
    return list(rows.values())


# ---------------------------------------------------------------------------------------------- output
def fmt(value: float | None) -> str:
    if value is None:
        return "-"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    if abs(value) >= 10:
        return f"{value:.1f}"
    return f"{value:.3g}"


def print_rows(script: str, rows: list[Row], show_all: bool, note: str = "") -> None:
    shown = [r for r in rows if show_all or "(derived)" not in r.unit]
    table = [(r.key, r.unit, fmt(r.old_best), fmt(r.new_best),
              "-" if r.speed is None else f"{r.speed:.3f}x", f"{100 * r.noise:.0f}%",
              "<-- SLOWER" if r.flagged else ("(control)" if "(control)" in r.unit and r.speed else ""))
             for r in shown]
    headers = ("key", "unit", "old", "new", "speed new/old", "noise", "")
    widths = [max(len(h), *(len(t[i]) for t in table)) if table else len(h) for i, h in enumerate(headers)]
    counts = f"{max(len(r.old) for r in rows)} old / {max(len(r.new) for r in rows)} new runs" if rows else "no runs"
    print(f"\n== {script} (best of {counts}{'; ' + note if note else ''}; speed > 1 = new is faster / smaller)")
    print(" | ".join(h.ljust(w) for h, w in zip(headers, widths)).rstrip())
    print("-|-".join("-" * w for w in widths))
    for line in table:
        cells = [c.rjust(w) if 2 <= i <= 5 else c.ljust(w) for i, (c, w) in enumerate(zip(line, widths))]
        print(" | ".join(cells).rstrip())
    flagged = [r.key for r in rows if r.flagged]
    print(f"{len(flagged)} of {sum(1 for r in rows if r.sense != NONE and '(control)' not in r.unit)} judged rows "
          f"below {FLAG_BELOW}x" + (f": {', '.join(flagged)}" if flagged else ""))


def write_json_atomic(path: Path, data: dict) -> None:
    """Write through a temporary file and a rename, so a reader never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)

"""Issue 56: the pixel reference runs' table of docs/pixel-results.md, from one test-split evaluation.

Reads the JSON of ``continuum-gym evaluate --pixel-metrics --split test --json FILE`` (or several, one per env:
their envs are merged, a later file's env replacing an earlier one's) run on a folder that holds,
per env, the state residuals and the pixel residuals on the same base (``select.sh`` links them), and writes
the table between the ``pixel-runs`` markers of ``docs/pixel-results.md``: per pixel row its seeds, headline
metric, pixel metric, its base's and the state residual's headline metric, whether the pixel row's CI is
separated from its base's (the issue's "beats its base with separated CIs"), and the gain recovered:
(pixel - base) / (state - base) on the headline metric, the share of the state residual's gain pixels keep.

    python experiments/pixels/report.py ~/campaigns/pixels/final/results.json [vt.json ...]
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs" / "pixel-results.md"
MARKERS = ("<!-- pixel-runs:start -->", "<!-- pixel-runs:end -->")
#: env id -> (headline metric, lower is better, the pixel metric, its scale to per cent)
ENVS = {
    "ContinuumGym/OcclusionAvoidance-v0": ("mean_voi", True, "mean_image_occlusion", 100.0),
    "ContinuumGym/ViewTracking-v0": ("mean_or", False, "mean_view_centre_error_pct", 1.0),
}


def cell(stats: dict | None, fmt: str = "{:.3f}", scale: float = 1.0, unit: str = "") -> str:
    if not stats or stats.get("mean") is None:
        return "-"
    text = fmt.format(stats["mean"] * scale) + unit
    if stats.get("ci_low") is not None:
        text += f" [{fmt.format(stats['ci_low'] * scale)}, {fmt.format(stats['ci_high'] * scale)}]"
    return text


def separated(row: dict, base: dict, lower_is_better: bool) -> bool:
    """The row's 95 % CI lies wholly on the better side of its base's."""
    if lower_is_better:
        return row["ci_high"] < base["ci_low"]
    return row["ci_low"] > base["ci_high"]


def rows(results: dict) -> list[str]:
    out = ["| env | row | seeds | headline [95 % CI] | pixel metric [95 % CI] | base | state residual | "
           "beats its base, CIs separated | gain recovered |", "|---|---|---|---|---|---|---|---|---|"]
    for env_id, (metric, lower, pixel_metric, scale) in ENVS.items():
        table = results.get(env_id, {})
        for name, row in table.items():
            if not name.endswith("_rgbd") or metric not in row:
                continue
            base_name = row["probability_of_improvement"]["over"]
            base, state = table[base_name], table.get(name[: -len("_rgbd")])
            gain = "-"
            if state is not None and state[metric]["mean"] != base[metric]["mean"]:
                gain = f"{(row[metric]['mean'] - base[metric]['mean']) / (state[metric]['mean'] - base[metric]['mean']):.2f}"
            short = env_id.split("/")[1]
            out.append(
                f"| {short} | `{name}` | {row.get('n_seeds', '-')} | {cell(row[metric])} | "
                f"{cell(row.get(pixel_metric), '{:.1f}', scale, ' %')} | `{base_name}` {cell(base[metric])} | "
                + (f"{cell(state[metric])} ({state.get('n_seeds', '-')} seeds) | " if state else "- | ")
                + f"{'yes' if separated(row[metric], base[metric], lower) else 'no'} | {gain} |")
    return out


def main(*paths: str) -> int:
    if not paths:
        raise SystemExit("usage: report.py RESULTS.json [MORE.json ...]")
    results: dict = {}
    for path in paths:
        results.update(json.loads(Path(path).read_text()))
    text = DOCS.read_text()
    start, end = (re.escape(marker) for marker in MARKERS)
    block = "\n".join([MARKERS[0], *rows(results), MARKERS[1]])
    new, count = re.subn(f"{start}.*?{end}", lambda _: block, text, flags=re.S)
    if count != 1:
        raise SystemExit(f"{DOCS}: expected one pair of {MARKERS} markers, found {count}")
    DOCS.write_text(new)
    print(block)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))

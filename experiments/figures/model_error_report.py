"""Issue 37: the baselines' (and shipped policies') degradation under model error, as a table and a figure.

Reads the JSON of ``continuum-gym evaluate --model-error <level> --json <dir>/eval_<level>.json`` for the
levels none, mild and severe, and writes the results table of ``docs/model-error.md`` (between its
``results`` markers: mean [95 % CI] of the tip / target-point error, VOI, OR and coverage per method and
level) and ``docs/img/model_error_headline.png`` (each method's headline metric against the error level).

    python experiments/figures/model_error_report.py /tmp/me   # the directory holding eval_none.json, eval_mild.json, ...
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

LEVELS = ("none", "mild", "severe")
REFERENCES = ("offline_optimum", "bounded_least_squares")
DOCS = Path(__file__).resolve().parents[2] / "docs"
COLUMNS = {
    "ContinuumGym/OcclusionAvoidance-v0": (("mean_tip_error_m", "tip error (mm)", 1e3), ("mean_voi", "VOI", 1.0),
                                           ("tip_in_view_fraction", "tip in view", 1.0)),
    "ContinuumGym/ViewTracking-v0": (("mean_position_error_m", "target-point error (mm)", 1e3),
                                     ("mean_or", "OR", 1.0), ("coverage_percent", "coverage (%)", 1.0)),
}


def cell(stats: dict | None, scale: float) -> str:
    if not stats or stats.get("mean") is None:
        return "-"
    text = f"{stats['mean'] * scale:.3g}"
    if stats.get("ci_low") is not None and stats.get("ci_high") is not None:
        text += f" [{stats['ci_low'] * scale:.3g}, {stats['ci_high'] * scale:.3g}]"
    return text


def main(directory: str) -> int:
    from continuum_gym.envs.spec import get_spec

    data = {level: json.loads((Path(directory) / f"eval_{level}.json").read_text()) for level in LEVELS}
    lines = ["<!-- written by experiments/figures/model_error_report.py from continuum-gym evaluate --model-error "
             "none|mild|severe (test split, 32 episodes per task set, 21 x 21 coverage grid) -->", ""]
    for env_id, columns in COLUMNS.items():
        spec = get_spec(env_id)
        methods = [m for m in data["none"][env_id] if isinstance(data["none"][env_id][m], dict)
                   and any(key in data["none"][env_id][m] for key, _, _ in columns)]
        lines += [f"**{spec.short_name}**", "",
                  "| method | model error | " + " | ".join(label for _, label, _ in columns) + " |",
                  "|---|---|" + "---|" * len(columns)]
        for method in methods:
            if method in REFERENCES:  # the nominal task's ceiling, the same at every level
                row = data["none"][env_id][method]
                lines.append(f"| `{method}` | reference (nominal task) | " + " | ".join(
                    cell(row.get(key), scale) for key, _, scale in columns) + " |")
                continue
            for level in LEVELS:
                row = data[level][env_id].get(method, {})
                lines.append(f"| `{method}` | {level} | " + " | ".join(cell(row.get(key), scale)
                                                                      for key, _, scale in columns) + " |")
        lines.append("")
    page = DOCS / "model-error.md"
    text = page.read_text()
    start, end = "<!-- results:start -->\n", "<!-- results:end -->"
    head, rest = text.split(start)
    page.write_text(head + start + "\n".join(lines) + "\n" + end + rest.split(end, 1)[1])
    figure(data)
    print("wrote the table of docs/model-error.md and docs/img/model_error_headline.png")
    return 0


def figure(data: dict) -> None:
    import matplotlib

    from continuum_gym.envs.benchmark import benchmark_of

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from continuum_gym.envs.spec import get_spec

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, env_id in zip(axes, COLUMNS):
        spec = get_spec(env_id)
        metric = spec.metric(benchmark_of(spec).headline_metric)
        scale = metric.display_scale
        for method, stats in data["none"][env_id].items():
            if not isinstance(stats, dict) or metric.name not in stats or method in REFERENCES:
                continue
            means, lows, highs = [], [], []
            for level in LEVELS:
                s = data[level][env_id].get(method, {}).get(metric.name) or {}
                means.append((s.get("mean") or float("nan")) * scale)
                lows.append((s.get("ci_low") if s.get("ci_low") is not None else s.get("mean") or 0.0) * scale)
                highs.append((s.get("ci_high") if s.get("ci_high") is not None else s.get("mean") or 0.0) * scale)
            errors = [[m - lo for m, lo in zip(means, lows)], [hi - m for m, hi in zip(means, highs)]]
            ax.errorbar(range(len(LEVELS)), means, yerr=errors, marker="o", capsize=3, label=method)
        ax.set_xticks(range(len(LEVELS)), [f"{level}" for level in LEVELS])
        ax.set_xlabel("model error preset (docs/model-error.md)")
        ax.set_ylabel(metric.axis_label())
        ax.set_title(f"{spec.short_name} (test split; mean, 95 % CI)", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    (DOCS / "img").mkdir(exist_ok=True)
    fig.savefig(DOCS / "img" / "model_error_headline.png", dpi=120)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "."))

"""Figures of ``continuum-gym evaluate``: none is written empty, and no label is cut off at the figure's edge."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from matplotlib.figure import Figure

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import ENV_SPECS, get_spec
from continuum_gym.evaluation.figures import draw, draw_learning_curves

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"


def _results(spec, tasks, runs=2, episodes=4):
    """Synthetic results of two methods on ``tasks`` (the shape evaluate_env returns), with traces where recorded."""
    rng = np.random.default_rng(0)
    results = {}
    for method in ("baseline", "residual"):
        results[method] = {}
        for task in tasks:
            traces = [{f"trace_{benchmark_of(spec).trace_value}": rng.random(50)} for _ in range(runs)] \
                if task == benchmark_of(spec).trace_task else []
            results[method][task] = {"scores": {benchmark_of(spec).headline_metric: [rng.random(episodes) for _ in range(runs)]},
                                     "traces": traces, "grid": False}
    return results


def test_a_split_without_the_trace_task_writes_no_trace_figure_and_no_legend_warning(tmp_path, monkeypatch):
    spec = get_spec(OCCLUSION)
    titles, real_savefig = [], Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: (titles.append(fig.axes[0].get_title()),
                                                                 real_savefig(fig, *a, **k))[1])
    assert benchmark_of(spec).trace_task in spec.config_class.test_only_tasks  # the circle is a test-only task
    (tmp_path / "validation").mkdir()
    (tmp_path / "test").mkdir()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        written = draw(OCCLUSION, _results(spec, ["hold"]), {}, {}, tmp_path / "validation", "validation")
    trace = f"OcclusionAvoidance_{benchmark_of(spec).trace_task}_trace.png"
    assert not (tmp_path / "validation" / trace).exists() and all(path.name != trace for path in written)
    assert not [w for w in caught if "No artists with labels" in str(w.message)]
    assert {path.name for path in written} == {"OcclusionAvoidance_distribution.png",
                                               "OcclusionAvoidance_performance_profiles.png"}
    assert "(held-out validation tasks)" in titles[0]  # the split evaluated, not "test"
    # On the test split the trace is there, with a line per method.
    written = draw(OCCLUSION, _results(spec, ["hold", benchmark_of(spec).trace_task]), {}, {}, tmp_path / "test")
    assert (tmp_path / "test" / trace) in written and (tmp_path / "test" / trace).stat().st_size > 0


@pytest.mark.parametrize("timed", [False, True], ids=["steps", "steps_and_wall_clock"])
@pytest.mark.parametrize("env_id", sorted(ENV_SPECS))
def test_the_learning_curves_labels_lie_inside_the_figure(env_id, timed, tmp_path, monkeypatch):
    """The axis labels, titles and legend texts are inside the saved canvas, not cut at its edge."""
    spec = get_spec(env_id)
    runs = []
    for seed in range(2):
        run = tmp_path / f"run{seed}"
        run.mkdir()
        steps = np.arange(0, 1_000_001, 100_000)
        np.savez(run / "evaluations.npz", timesteps=steps, **{benchmark_of(spec).headline_metric: 0.2 + 0.01 * seed - 5e-8 * steps})
        if timed:
            (run / "wall_clock.csv").write_text("timesteps,elapsed_s\n" + "".join(f"{s},{s / 1e3}\n" for s in steps))
        runs.append(run)
    checked = []
    real_savefig = Figure.savefig

    def savefig(fig, *args, **kwargs):
        fig.set_dpi(kwargs.get("dpi", fig.dpi))  # as savefig draws it: text sizes round to the pixels of its dpi
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        canvas = fig.bbox
        texts = [fig._suptitle] if fig._suptitle is not None else []
        for ax in fig.axes:
            legend = ax.get_legend()
            texts += [ax.xaxis.label, ax.yaxis.label, ax.title, *(legend.get_texts() if legend else [])]
        for text in texts:
            if not text.get_visible() or not text.get_text():
                continue
            box = text.get_window_extent(renderer)
            inside = box.x0 >= canvas.x0 - 1 and box.y0 >= canvas.y0 - 1 and box.x1 <= canvas.x1 + 1 \
                and box.y1 <= canvas.y1 + 1
            assert inside, f"{text.get_text()!r} at {box.bounds} is cut off by the figure ({canvas.bounds})"
            checked.append(text.get_text())
        return real_savefig(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    path = draw_learning_curves(spec, {env_id: {"residual_projected_gradient": runs}}, tmp_path / "curves.png", env_id)
    assert path is not None and path.is_file()
    assert any("better" in text for text in checked)  # the y label was among the texts checked

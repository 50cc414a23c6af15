"""Figures of the offline optima: coverage maps, hold starts, the circle's bound."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from continuum_gym.baselines.scenarios import COVERAGE_THRESHOLD


# ====================================================================== figures
def draw_coverage_maps(coverage: dict, path: Path | str) -> Path:
    """2 x 2 OR maps (optimum, bounded LSQ, DR, RMRC) over yaw x pitch with the OR = 0.8 contour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = int(coverage["grid"])
    axis = np.degrees(np.linspace(-math.pi / 3, math.pi / 3, n))
    panels = [("optimum", "offline optimum"), ("bounded_least_squares", "bounded least squares"),
              ("dimension_reduced", "dimension-reduced IK"), ("resolved_rate", "resolved rate (RMRC)")]
    fig, axes = plt.subplots(2, 2, figsize=(10, 9), constrained_layout=True)
    image = None
    for ax, (key, title) in zip(axes.ravel(), panels):
        values = np.asarray(coverage[f"{key}_or"]).reshape(n, n)  # [yaw, pitch]
        image = ax.imshow(values.T, origin="lower", extent=(axis[0], axis[-1], axis[0], axis[-1]),
                          vmin=0.0, vmax=1.0, cmap="viridis", interpolation="nearest", aspect="equal")
        ax.contour(axis, axis, values.T, levels=[coverage.get("threshold", COVERAGE_THRESHOLD)], colors="w",
                   linewidths=1.2)
        percent = float(np.mean(values > coverage.get("threshold", COVERAGE_THRESHOLD)) * 100)
        ax.set_title(f"{title}: {percent:.1f} % (mean OR {values.mean():.3f})")
        ax.set_xlabel("yaw (deg)")
        ax.set_ylabel("pitch (deg)")
    assert image is not None  # drawn by each of the four panels
    fig.colorbar(image, ax=axes, shrink=0.8, label="overlap ratio OR")
    fig.suptitle(f"Coverage {n} x {n} (L_dV = 65 mm, roll 0); white: OR = 0.8")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_hold(hold: dict, path: Path | str) -> Path:
    """Per-start VOI: start, projected gradient (final), self-motion at centring gamma, optimum."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    optimum = np.asarray(hold["optimum_voi"], dtype=float)
    order = np.argsort(np.nan_to_num(optimum, nan=np.inf))
    x = np.arange(len(order))
    fig, ax = plt.subplots(figsize=(11, 4.5), constrained_layout=True)
    ax.plot(x, np.asarray(hold["start_voi"])[order], "k.", label="start (gamma 0)")
    ax.plot(x, np.asarray(hold["projected_gradient_final_voi"])[order], "o", mfc="none", color="tab:red",
            label=f"projected gradient, final (median {hold['projected_gradient_median_voi']:.3f})")
    ax.plot(x, np.asarray(hold["centring_gamma_voi"])[order], "s", mfc="none", color="tab:blue", ms=4,
            label=f"self-motion optimum, centring gamma (median {hold['centring_gamma_median_voi']:.3f})")
    ax.bar(x, optimum[order], color="tab:green", alpha=0.7,
           label=f"offline optimum, gamma free (median {hold['optimum_median_voi']:.3f})")
    ax.set_xlabel("hold start (sorted by optimum)")
    ax.set_ylabel("VOI")
    ax.set_title(f"Hold: {hold['n_starts']} starts (seed {hold['starts_seed']}), bends <= "
                 f"{math.degrees(hold['limits']['max_bend']):.0f} deg, tip within {hold['visibility']} beta")
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_circle(circle: dict, path: Path | str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(circle["times"])
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    ax.plot(t, circle["optimum_voi"], color="tab:green",
            label=f"optimum, gamma free (mean {circle['optimum_mean_voi']:.3f})")
    ax.plot(t, circle["centring_gamma_voi"], color="tab:blue",
            label=f"optimum, centring gamma (mean {circle['centring_gamma_mean_voi']:.3f})")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("VOI")
    ax.set_title("Circle (task b): time-connected lower bound within the env limits")
    ax.legend()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_hold_test(hold_test: dict, rate_bound: dict | None, path: Path | str, title: str = "") -> Path:
    """Per held-out hold task: the offline optimum's VOI and, where computed, the rate-limited bound and the
    planned trajectory's episode-mean VOI (``hold_test`` and ``hold_test_rate_bound`` of an optimum cache)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    optimum = np.asarray(hold_test["optimum_voi"], dtype=float)
    order = np.argsort(np.nan_to_num(optimum, nan=np.inf))
    x = np.arange(len(order))
    fig, ax = plt.subplots(figsize=(9, 4.2), constrained_layout=True)
    ax.bar(x, optimum[order], color="tab:green", alpha=0.7,
           label=f"offline optimum (mean {np.nanmean(optimum):.3f})")
    if rate_bound is not None:
        for key, marker, color, words in (("mean_voi_bound", "v", "tab:red", "rate-limited bound, episode mean"),
                                          ("mean_voi_plan", "o", "tab:blue", "planned trajectory, episode mean")):
            values = np.asarray(rate_bound[key], dtype=float)[order]
            ax.plot(x, values, marker, mfc="none", color=color, label=f"{words} (mean {np.mean(values):.3f})")
    ax.set_xticks(x, [str(hold_test["task_ids"][k]) for k in order], fontsize=7)
    ax.set(xlabel="held-out hold task id (sorted by the optimum)", ylabel="VOI, lower is better",
           title=title or f"Offline optimum of {len(x)} held-out hold tasks")
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

"""VOI vs pixel occlusion: the paper's geometric index against the fraction of the endoscope image covered.

    python experiments/figures/voi_vs_pixel_occlusion.py [--n 300] [--out DIR] [--resolution 128] [--seed 0]

Draws ``n`` hold-task starts (``sample_hold_starts``) spread over VOI targets 0.05..0.65 (at gamma = 0),
evaluates each at gamma = 0 and at a random gamma, and compares the VOI (eq 27) with the pixel occlusion
rendered by pybullet (``continuum_gym.render.pixel_occlusion``). Writes ``voi_vs_pixel_occlusion.png``
(scatter plots), ``voi_vs_pixel_occlusion.json`` (correlations, binned statistics, raw data) and
``extremes.png`` (endoscope images where VOI over- and under-states the pixel coverage most) to DIR.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from scipy.stats import pearsonr, spearmanr
from tqdm import tqdm

from continuum_gym.baselines.scenarios import sample_hold_starts
from continuum_gym.geometry.lens_cone import cone_coordinates, lens_origin
from continuum_gym.geometry.occlusion import occlusion_details
from continuum_gym.render import OcclusionScene
from continuum_gym.robots import MultiBackboneRobot

VOI_TARGETS = (0.05, 0.15, 0.25, 0.35, 0.45, 0.55, 0.65)


def correlations(voi, pixels):
    if len(voi) < 3 or np.ptp(voi) == 0 or np.ptp(pixels) == 0:
        return {"n": int(len(voi)), "spearman": None, "pearson": None}
    return {"n": int(len(voi)), "spearman": float(spearmanr(voi, pixels)[0]),
            "pearson": float(pearsonr(voi, pixels)[0])}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=300, help="hold starts (each at gamma 0 and a random gamma)")
    parser.add_argument("--out", default="results/voi_vs_pixel_occlusion", help="output directory")
    parser.add_argument("--resolution", type=int, default=128, help="endoscope image side (pixels)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    robot = MultiBackboneRobot()
    rng = np.random.default_rng(args.seed)
    per_target = np.diff(np.linspace(0, args.n, len(VOI_TARGETS) + 1).round().astype(int))
    starts = [sample_hold_starts(robot, int(k), rng, voi_target=v, voi_tolerance=0.05)
              for v, k in tqdm(list(zip(VOI_TARGETS, per_target)), desc="hold starts", unit="target") if k > 0]
    Q0 = np.concatenate(starts)
    Q = np.concatenate([Q0, Q0])
    gamma = np.concatenate([np.zeros(len(Q0)), rng.uniform(-math.pi, math.pi, len(Q0))])
    details = occlusion_details(robot, Q, gamma)
    voi = details["voi"]

    # geometry of what is in view: distance from the lens of the backbone samples inside the cone
    points = robot.backbone(Q, 40)
    cone = cone_coordinates(points, gamma[:, None])
    inside = cone["angle"] < robot_beta()
    dist = np.linalg.norm(points - lens_origin(gamma)[:, None, :], axis=-1)
    mean_dist = np.where(inside.any(axis=1), np.sum(dist * inside, axis=1) / np.maximum(inside.sum(axis=1), 1), np.nan)
    inside_fraction = inside.mean(axis=1)

    scene = OcclusionScene(tissue=None)
    pixels = np.empty(len(Q))
    for i in tqdm(range(len(Q)), desc="pixel occlusion", unit="cfg"):
        scene.update(Q[i], gamma[i])
        pixels[i] = scene.pixel_occlusion(args.resolution)
    scene.close()

    g0 = gamma == 0.0
    nonzero = voi > 0
    summary = {
        "n_configurations": int(len(Q0)), "n_evaluations": int(len(Q)), "resolution": args.resolution,
        "seed": args.seed, "voi_targets": VOI_TARGETS,
        "all": correlations(voi, pixels),
        "gamma_0": correlations(voi[g0], pixels[g0]),
        "gamma_random": correlations(voi[~g0], pixels[~g0]),
        "voi_positive": correlations(voi[nonzero], pixels[nonzero]),
        "voi_zero": {"n": int((~nonzero).sum()), "pixel_mean": float(pixels[~nonzero].mean()) if (~nonzero).any()
                     else None, "pixel_max": float(pixels[~nonzero].max()) if (~nonzero).any() else None,
                     "fraction_pixel_above_0.01": float((pixels[~nonzero] > 0.01).mean()) if (~nonzero).any()
                     else None},
    }
    # least-squares slope through the origin and binned statistics
    summary["slope_pixel_per_voi"] = float(np.sum(voi * pixels) / np.sum(voi * voi))
    bins = np.array([0.0, 1e-12, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 1.0001])
    binned = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        sel = (voi >= lo) & (voi < hi)
        if sel.any():
            q25, q50, q75 = np.percentile(pixels[sel], [25, 50, 75])
            binned.append({"voi_from": float(lo), "voi_to": float(hi), "n": int(sel.sum()), "pixel_median": float(q50),
                           "pixel_q25": float(q25), "pixel_q75": float(q75)})
    summary["binned"] = binned
    # what the disagreement depends on: log ratio pixel/VOI against the distance of the robot in view
    ok = nonzero & (pixels > 0) & np.isfinite(mean_dist)
    log_ratio = np.log(pixels[ok] / voi[ok])
    summary["log_ratio_vs_mean_distance_spearman"] = float(spearmanr(log_ratio, mean_dist[ok])[0])
    summary["log_ratio_vs_r_max_spearman"] = float(spearmanr(log_ratio, details["r_max"][ok])[0])
    summary["log_ratio_vs_nu_spearman"] = float(spearmanr(log_ratio, details["nu"][ok])[0])
    summary["pixel_over_voi_median"] = float(np.exp(np.median(log_ratio)))
    summary["raw"] = {"q": Q, "gamma": gamma, "voi": voi, "pixel_occlusion": pixels, "nu": details["nu"],
                      "r_e": details["r_e"], "r_max": details["r_max"], "mean_distance_in_view": mean_dist,
                      "inside_fraction": inside_fraction}
    (out / "voi_vs_pixel_occlusion.json").write_text(json.dumps(summary, indent=1, default=_jsonable) + "\n")
    _plot(out / "voi_vs_pixel_occlusion.png", voi, pixels, g0, mean_dist, summary)
    _extremes(out / "extremes.png", robot, Q, gamma, voi, pixels, ok, log_ratio)

    print(f"{len(Q0)} hold starts x (gamma 0, random gamma), {args.resolution}x{args.resolution} endoscope images")
    for key in ("all", "gamma_0", "gamma_random", "voi_positive"):
        c = summary[key]
        print(f"  {key:13s} n={c['n']:4d}  Spearman {c['spearman']:.3f}  Pearson {c['pearson']:.3f}")
    z = summary["voi_zero"]
    print(f"  VOI = 0: n={z['n']}, pixel occlusion mean {z['pixel_mean']:.4f}, max {z['pixel_max']:.4f}")
    print(f"  pixel occlusion ~ {summary['slope_pixel_per_voi']:.3f} x VOI (least squares through 0); "
          f"median pixel/VOI {summary['pixel_over_voi_median']:.3f}")
    print("  Spearman of log(pixel/VOI) with the mean distance of the robot in view "
          f"{summary['log_ratio_vs_mean_distance_spearman']:.3f}, "
          f"with r_max {summary['log_ratio_vs_r_max_spearman']:.3f}, with nu {summary['log_ratio_vs_nu_spearman']:.3f}")
    for b in binned:
        print(f"  VOI [{b['voi_from']:.2f}, {b['voi_to']:.2f}): n={b['n']:4d}  pixel median {b['pixel_median']:.3f} "
              f"(IQR {b['pixel_q25']:.3f}-{b['pixel_q75']:.3f})")
    print(f"wrote {out}/voi_vs_pixel_occlusion.png, .json, extremes.png")
    return 0


def robot_beta():
    from continuum_gym.geometry.lens_cone import DEFAULT_CONE

    return DEFAULT_CONE.beta


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return np.where(np.isfinite(value), value, None).tolist() if value.dtype.kind == "f" else value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def _plot(path, voi, pixels, g0, mean_dist, summary):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    ax = axes[0]
    ax.scatter(voi[g0], pixels[g0], s=12, alpha=0.7, label="gamma = 0 (sampled VOI)")
    ax.scatter(voi[~g0], pixels[~g0], s=12, alpha=0.7, marker="x", label="random gamma")
    slope = summary["slope_pixel_per_voi"]
    ax.plot([0, 1], [0, slope], "k--", lw=1, label=f"least squares: {slope:.2f} VOI")
    c = summary["all"]
    ax.set(xlabel="VOI (eq 27)", ylabel="pixel occlusion (fraction of circular FOV)",
           title=f"Spearman {c['spearman']:.2f}, Pearson {c['pearson']:.2f} (n={c['n']})", xlim=(-0.02, 1.02))
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[1]
    ok = (voi > 0) & (pixels > 0) & np.isfinite(mean_dist)
    sc = ax.scatter(voi[ok], pixels[ok] / voi[ok], c=1e3 * mean_dist[ok], s=12, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="mean distance of the robot in view from the lens (mm)")
    ax.axhline(summary["pixel_over_voi_median"], color="k", ls="--", lw=1, label="median")
    ax.set(xscale="linear", yscale="log", xlabel="VOI", ylabel="pixel occlusion / VOI",
           title="where VOI over- (low) and under-states (high) the coverage")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _extremes(path, robot, Q, gamma, voi, pixels, ok, log_ratio, k=3, size=160):
    """Endoscope images of the configurations with the lowest and highest pixel/VOI."""
    import imageio.v3 as iio

    idx = np.flatnonzero(ok)
    order = np.argsort(log_ratio)
    picks = list(idx[order[:k]]) + list(idx[order[-k:]])
    scene = OcclusionScene(robot=robot)
    tiles = []
    for i in picks:
        scene.update(Q[i], gamma[i])
        tiles.append(np.concatenate([scene.render("endoscope", size, size), scene.render("external", size, size)], 0))
    scene.close()
    rows = [np.concatenate(tiles[:k], 1), np.concatenate(tiles[k:], 1)]
    iio.imwrite(path, np.concatenate(rows, 0))
    return [(int(i), float(voi[i]), float(pixels[i])) for i in picks]


if __name__ == "__main__":
    raise SystemExit(main())

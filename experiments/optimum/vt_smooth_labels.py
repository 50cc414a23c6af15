"""Do continuation labels make the ViewTracking-v0 optimum smooth without losing coverage?

Measures, on an OFFSET grid of G x G pan_tilt targets [COVERAGE_INSERTION, yaw, pitch, 0] with
yaw/pitch = -pi/3 + (j + 0.5) (2 pi/3) / G (that no point coincides with the 21 x 21 test grid is
asserted: G = 24, 32, 40 pass, G = 2 and 6 do not), two label sets of residual-holdable configurations (residual scale 3):

1. independent: ``view_tracking_optimum`` per target, then ``holdable_optimum(q, targets, 3.0)``
   (cached as ``independent_G{G}_{effort}.npz`` in --out, so reruns skip it);
2. continuation (one per --lam): the grid visited in serpentine order; the first target takes the
   independent label, every next one minimises (Nelder-Mead, joints clipped to the limits)
   ``-OR(q) + PENALTY * max(0, effort(q) - HOLD_MARGIN) + lam * sum_n |wrapdiff(q - q_n)|^2``
   over its already-solved 4-neighbours q_n (the serpentine predecessor and the previous row's
   neighbour; L0 scaled by 1/0.1 m), started from each of those neighbours; the better objective is kept.

Metrics per label set: coverage (% targets with OR > 0.8 and hold effort <= 1), mean OR, smoothness over
all horizontal + vertical neighbour pairs (max over the angle joints of the wrapped difference, rad:
median, p90, share > 0.5 rad; L0 difference in m separately; and with L0 scaled by 1/0.1 m), a "physical"
jump (max of |d phi|, 10 |d L0| and each segment's bend-vector change |theta (cos delta, sin delta)|, which
ignores delta where its bend is ~0), and the share
of targets where continuation loses > 0.02 OR against the independent label.

Run (one core):
    cd /work/main && OMP_NUM_THREADS=1 PYTHONPATH=. python experiments/optimum/vt_smooth_labels.py \
        --grid 24 --effort quick --lam 0 1e-3 --out /work/campaigns/optimum/c11/smooth
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from residual_reach import HOLD_MARGIN, PENALTY, HoldEffort, holdable_optimum
from scipy.optimize import minimize

from continuum_gym.baselines import make_controller
from continuum_gym.baselines.scenarios import COVERAGE_INSERTION, COVERAGE_THRESHOLD
from continuum_gym.evaluation.optimum.view import overlap_of_configuration, view_tracking_optimum
from continuum_gym.geometry.frustum import Frustum
from continuum_gym.robots import DaVinciEndoscope

RESIDUAL_SCALE = 3.0
L0_SCALE = 1.0 / 0.1  # L0 (m) -> comparable to rad
ANGLES = [1, 2, 3, 4, 5]
LOSS_TOLERANCE = 0.02
SMOOTH_LIMIT = 0.5


def offset_targets(G: int, L: float = COVERAGE_INSERTION, roll: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(G*G, 4) targets at insertion L and roll (yaw-major: index i*G + j is yaw_i, pitch_j) and the axis (G,)."""
    if G % 2:
        raise ValueError("G must be even")
    axis = -math.pi / 3 + (np.arange(G) + 0.5) * (2 * math.pi / 3) / G
    test_axis = -math.pi / 3 + np.arange(21) * (2 * math.pi / 3) / 20
    gap = np.min(np.abs(axis[:, None] - test_axis[None, :]))
    assert gap > 1e-6, f"offset grid touches the test grid (min axis gap {gap})"
    yaw, pitch = np.meshgrid(axis, axis, indexing="ij")
    targets = np.stack([np.full(yaw.size, L), yaw.ravel(), pitch.ravel(), np.full(yaw.size, roll)], axis=1)
    return targets, axis


def wrapdiff(a: np.ndarray, b: np.ndarray, scale_l0: bool = True) -> np.ndarray:
    """a - b with the angle joints wrapped to [-pi, pi); L0 scaled by L0_SCALE if scale_l0."""
    d = np.array(a, dtype=float) - np.array(b, dtype=float)
    d[..., ANGLES] = (d[..., ANGLES] + math.pi) % (2 * math.pi) - math.pi
    if scale_l0:
        d[..., 0] *= L0_SCALE
    return d


def wrap_q(q: np.ndarray) -> np.ndarray:
    q = np.array(q, dtype=float)
    q[..., [3, 5]] = (q[..., [3, 5]] + math.pi) % (2 * math.pi) - math.pi
    return q


class Problem:
    """OR and hold effort of configurations towards each target (the holdable_optimum objective)."""

    def __init__(self, targets: np.ndarray) -> None:
        self.controller = make_controller("dimension_reduced")
        self.frustum, davinci = Frustum(), DaVinciEndoscope()
        self.p_a, self.R_a = davinci.forward_kinematics(targets)
        self.p_t, self.R_t = davinci.target_pose(targets)
        self.robot = self.controller.robot.kernel_args()
        self.lower, self.upper = self.controller.robot.joint_limits
        self.effort_kernel = HoldEffort(self.controller, RESIDUAL_SCALE)

    def overlap(self, q, k):
        f = self.frustum
        return overlap_of_configuration(np.ascontiguousarray(q, dtype=float), self.p_a[k], self.R_a[k], self.robot,
                                        f.tan_half, f.near, f.far)

    def effort(self, q, k):
        return self.effort_kernel(np.ascontiguousarray(q, dtype=float), self.p_t[k], self.R_t[k])

    def clip(self, q):
        return np.clip(q, self.lower, self.upper)


def continuation(problem: Problem, G: int, q_first: np.ndarray, lam: float, maxfev: int) -> np.ndarray:
    """Serpentine continuation labels (G*G, 6)."""
    n = G * G
    q_out = np.full((n, 6), np.nan)
    order = [(i, j if i % 2 == 0 else G - 1 - j) for i in range(G) for j in range(G)]
    prev = None
    for step, (i, j) in enumerate(order):
        k = i * G + j
        if step == 0:
            q_out[k] = q_first
            prev = k
            continue
        anchors = [prev]
        if i > 0 and (i - 1) * G + j != prev:
            anchors.append((i - 1) * G + j)
        anchor_q = [q_out[a] for a in anchors]

        def objective(q, k=k, anchor_q=anchor_q):
            q = problem.clip(q)
            value = -problem.overlap(q, k) + PENALTY * max(0.0, problem.effort(q, k) - HOLD_MARGIN)
            if lam > 0:
                value += lam * sum(float(np.sum(wrapdiff(q, a) ** 2)) for a in anchor_q)
            return value

        best = None
        for x0 in anchor_q:
            result = minimize(objective, x0, method="Nelder-Mead",
                              options={"maxfev": maxfev, "xatol": 1e-6, "fatol": 1e-8})
            if best is None or result.fun < best.fun:
                best = result
        q_out[k] = wrap_q(problem.clip(best.x))
        prev = k
    return q_out


def evaluate(problem: Problem, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    overlaps = np.array([problem.overlap(q[k], k) for k in range(len(q))])
    efforts = np.array([problem.effort(q[k], k) for k in range(len(q))])
    return overlaps, efforts


def neighbour_pairs(G: int) -> np.ndarray:
    pairs = []
    for i in range(G):
        for j in range(G):
            if j + 1 < G:
                pairs.append((i * G + j, i * G + j + 1))
            if i + 1 < G:
                pairs.append((i * G + j, (i + 1) * G + j))
    return np.array(pairs)


def metrics(q: np.ndarray, overlaps: np.ndarray, efforts: np.ndarray, pairs: np.ndarray,
            reference_or: np.ndarray | None = None) -> dict:
    d = wrapdiff(q[pairs[:, 0]], q[pairs[:, 1]], scale_l0=False)
    angle_jump = np.max(np.abs(d[:, ANGLES]), axis=1)
    l0_jump = np.abs(d[:, 0])
    scaled_jump = np.maximum(angle_jump, l0_jump * L0_SCALE)
    per_joint = np.abs(d)
    covered = (overlaps > COVERAGE_THRESHOLD) & (efforts <= 1.0)
    out = {
        "coverage_percent": float(np.mean(covered) * 100),
        "mean_or": float(np.mean(overlaps)),
        "holdable_percent": float(np.mean(efforts <= 1.0) * 100),
        "smooth_angle_median_rad": float(np.median(angle_jump)),
        "smooth_angle_p90_rad": float(np.percentile(angle_jump, 90)),
        "smooth_angle_share_gt_0.5": float(np.mean(angle_jump > SMOOTH_LIMIT)),
        "smooth_angle_max_rad": float(np.max(angle_jump)),
        "smooth_L0_median_m": float(np.median(l0_jump)),
        "smooth_L0_p90_m": float(np.percentile(l0_jump, 90)),
        "smooth_scaled_share_gt_0.5": float(np.mean(scaled_jump > SMOOTH_LIMIT)),
        "share_gt_0.5_per_joint": [float(np.mean(per_joint[:, m] * (L0_SCALE if m == 0 else 1.0) > SMOOTH_LIMIT))
                                   for m in range(6)],
    }
    # delta is undefined when its bend is ~0: compare each segment's bend vector theta (cos delta, sin delta)
    def bend(qq, t, dl):
        return qq[:, t:t + 1] * np.stack([np.cos(qq[:, dl]), np.sin(qq[:, dl])], axis=1)
    qa, qb = q[pairs[:, 0]], q[pairs[:, 1]]
    bend_jump = np.maximum(np.linalg.norm(bend(qa, 2, 3) - bend(qb, 2, 3), axis=1),
                           np.linalg.norm(bend(qa, 4, 5) - bend(qb, 4, 5), axis=1))
    physical = np.maximum.reduce([bend_jump, np.abs(d[:, 1]), l0_jump * L0_SCALE])
    out.update({"physical_median": float(np.median(physical)), "physical_p90": float(np.percentile(physical, 90)),
                "physical_share_gt_0.5": float(np.mean(physical > SMOOTH_LIMIT))})
    if reference_or is not None:
        out["share_losing_gt_0.02_or"] = float(np.mean(overlaps < reference_or - LOSS_TOLERANCE))
        out["share_gaining_gt_0.02_or"] = float(np.mean(overlaps > reference_or + LOSS_TOLERANCE))
        out["mean_or_change"] = float(np.mean(overlaps - reference_or))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grid", type=int, default=24)
    parser.add_argument("--effort", default="quick", choices=["quick", "standard"])
    parser.add_argument("--lam", type=float, nargs="+", default=[0.0, 1e-3])
    parser.add_argument("--maxfev", type=int, default=1500, help="Nelder-Mead evaluations per continuation start")
    parser.add_argument("--out", default="/work/campaigns/optimum/c11/smooth")
    parser.add_argument("--tag", default="", help="suffix of summary/labels file names")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    G = args.grid
    targets, axis = offset_targets(G)
    problem = Problem(targets)
    pairs = neighbour_pairs(G)
    timings = {}

    cache = out / f"independent_G{G}_{args.effort}.npz"
    if cache.exists():
        data = np.load(cache)
        q_ind, or_ind, eff_ind = data["q"], data["overlap"], data["effort"]
        timings["independent_s"] = float(data["wall_s"])
        timings["independent_cached"] = True
        print(f"independent labels from cache {cache}")
    else:
        started = time.perf_counter()
        optimum = view_tracking_optimum(targets, effort=args.effort, workers=1, progress=False)
        t_opt = time.perf_counter() - started
        q_ind, or_ind, eff_ind = holdable_optimum(optimum["q"], targets, RESIDUAL_SCALE)
        q_ind = wrap_q(q_ind)
        wall = time.perf_counter() - started
        np.savez(cache, q=q_ind, overlap=or_ind, effort=eff_ind, q_star=optimum["q"], or_star=optimum["overlap"],
                 targets=targets, wall_s=wall, optimum_s=t_opt)
        timings["independent_s"] = wall
        timings["independent_optimum_s"] = t_opt
        timings["independent_cached"] = False
        print(f"independent labels: {wall:.0f} s (optimum {t_opt:.0f} s)", flush=True)

    summary = {"grid": G, "effort": args.effort, "spacing_rad": float(axis[1] - axis[0]), "n_targets": G * G,
               "n_pairs": len(pairs), "residual_scale": RESIDUAL_SCALE, "maxfev": args.maxfev,
               "L0_scale_per_m": L0_SCALE, "label_sets": {}, "timings_s": timings}
    summary["label_sets"]["independent"] = metrics(q_ind, or_ind, eff_ind, pairs)
    labels = {"targets": targets, "q_independent": q_ind, "or_independent": or_ind, "effort_independent": eff_ind}
    for lam in args.lam:
        started = time.perf_counter()
        q_c = continuation(problem, G, q_ind[0], lam, args.maxfev)
        or_c, eff_c = evaluate(problem, q_c)
        wall = time.perf_counter() - started
        name = f"continuation_lam{lam:g}"
        timings[name] = wall
        summary["label_sets"][name] = metrics(q_c, or_c, eff_c, pairs, reference_or=or_ind)
        labels[f"q_{name}"], labels[f"or_{name}"], labels[f"effort_{name}"] = q_c, or_c, eff_c
        print(f"{name}: {wall:.0f} s  {json.dumps(summary['label_sets'][name])}", flush=True)
    tag = f"_{args.tag}" if args.tag else ""
    (out / f"summary{tag}.json").write_text(json.dumps(summary, indent=2))
    np.savez(out / f"labels_G{G}_{args.effort}{tag}.npz", **labels)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()

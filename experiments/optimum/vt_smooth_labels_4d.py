"""Smooth (continuation) ViewTracking-v0 optimum labels over the 4-D target space [L_dV, yaw, pitch, roll].

Extends ``vt_smooth_labels.py`` (whose ``offset_targets``, ``Problem``, ``evaluate``, ``wrapdiff``, ``wrap_q``,
``metrics`` and ``neighbour_pairs`` it imports) from the 2-D pan_tilt grid to a 4-D grid:

* yaw/pitch: the G x G offset axis of ``offset_targets(G)`` (its no-test-grid assertion included), G = 40;
* L_dV: ``--n-length`` values evenly from ``--length-min`` to ``--length-max`` (default 7: 0.050, 0.055, ..., 0.080);
* roll: ``--n-roll`` values ``roll_min + (m + 0.5) (roll_max - roll_min) / n_roll`` (default 8 over [-pi/4, pi/4)).

Each (L_dV, roll) pair is a slice of G*G targets. Slices are visited starting at the L closest to
COVERAGE_INSERTION (0.065) and the roll closest to 0: for that roll, L outward (up, then down), then the next
roll outward (up, then down) with L outward again, so every slice after the first has an already-solved
neighbouring slice. Inside a slice the targets are visited in a 2-D serpentine (as ``continuation``); each
target minimises by Nelder-Mead (joints clipped to the limits) the objective

    -OR(q)                                          (default; the base controller holds what it steers to)
    -OR(q) + PENALTY * max(0, effort(q) - HOLD_MARGIN)   (with --holdable, as in vt_smooth_labels.py)

started from each of: its already-solved in-slice 4-neighbours (the serpentine predecessor, the previous row's
neighbour) and the same (yaw, pitch) point in every already-solved neighbouring slice (L +- 1 or roll +- 1;
``--slice-anchors parent`` uses only the slice it was continued from); the best objective is kept. The very
first target starts from ``view_tracking_optimum`` (effort standard) of that target.

Note on roll: ``q_davinci`` roll turns the 30-degree scope about its STEM axis, so it moves the optical axis;
OR is NOT invariant under roll -> roll + pi/2 of the target (only under 2 pi), so the roll grid must cover
the roll range used by the envs (static: [-pi/6, pi/6]; random: mostly within +-pi/4) and no roll wrap-around
is assumed.

Output in --out: ``slice_L{L:.3f}_r{m}.npz`` (targets, q, overlap, effort, wall_s, ...) per finished slice;
a rerun of the same command skips finished slices (resume). ``summary.json`` (rewritten after every slice):
per slice coverage (% OR > 0.8, and hold effort <= 1 with --holdable), mean OR, in-slice smoothness (share of
neighbour pairs whose wrapped angle-joint jump exceeds 0.5 rad, plus the other ``metrics`` fields), across-slice
smoothness (same (yaw, pitch) in L- and roll-adjacent slices), and wall times. When all slices are done (or with
``--check``) a sparse quality check: ``--check-n`` seeded random grid targets also get an independent
``view_tracking_optimum`` (standard) - share where the continuation OR is > 0.02 below it and the coverage of
both on that subset (cached in check_independent.npz).

Run (one core; the same command resumes):
    cd /work/main && OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=.:experiments/optimum \
        python experiments/optimum/vt_smooth_labels_4d.py --out /work/campaigns/optimum/c11/smooth4d
Smoke test:
    ... python experiments/optimum/vt_smooth_labels_4d.py --grid 4 --n-length 2 --n-roll 2 \
        --out /work/campaigns/optimum/c11/smooth4d_smoke
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from residual_reach import HOLD_MARGIN, PENALTY
from scipy.optimize import minimize
from vt_smooth_labels import (
    ANGLES,
    L0_SCALE,
    LOSS_TOLERANCE,
    SMOOTH_LIMIT,
    Problem,
    evaluate,
    metrics,
    neighbour_pairs,
    offset_targets,
    wrap_q,
    wrapdiff,
)

from continuum_gym.baselines.scenarios import COVERAGE_INSERTION, COVERAGE_THRESHOLD
from continuum_gym.evaluation.optimum.view import view_tracking_optimum


def grid_axes(args) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(yaw/pitch axis (G,), L values (nL,), roll values (nR,))."""
    _, axis = offset_targets(args.grid)  # asserts the offset axis does not touch the 21 x 21 test grid
    lengths = np.linspace(args.length_min, args.length_max, args.n_length)
    rolls = args.roll_min + (np.arange(args.n_roll) + 0.5) * (args.roll_max - args.roll_min) / args.n_roll
    return axis, lengths, rolls


def outward(n: int, start: int) -> list[int]:
    return list(range(start, n)) + list(range(start - 1, -1, -1))


def slice_order(lengths: np.ndarray, rolls: np.ndarray) -> tuple[list[tuple[int, int]], dict]:
    """Visit order of the (k, m) slices and the parent (the slice each is continued from) of each."""
    k0 = int(np.argmin(np.abs(lengths - COVERAGE_INSERTION)))
    m0 = int(np.argmin(np.abs(rolls)))
    order, parent = [], {}
    for m in outward(len(rolls), m0):
        for k in outward(len(lengths), k0):
            if m == m0:
                parent[(k, m)] = None if k == k0 else ((k - 1, m) if k > k0 else (k + 1, m))
            else:
                parent[(k, m)] = (k, m - 1) if m > m0 else (k, m + 1)
            order.append((k, m))
    return order, parent


def slice_path(out: Path, L: float, m: int) -> Path:
    return out / f"slice_L{L:.3f}_r{m}.npz"


def solve_slice(problem: Problem, G: int, slice_anchor_q: list[np.ndarray], q_first: np.ndarray | None,
                holdable: bool, maxfev: int) -> tuple[np.ndarray, np.ndarray]:
    """Serpentine continuation inside one slice. Returns q (G*G, 6) and the number of starts per target."""
    n = G * G
    q_out = np.full((n, 6), np.nan)
    n_starts = np.zeros(n, dtype=int)
    order = [(i, j if i % 2 == 0 else G - 1 - j) for i in range(G) for j in range(G)]
    prev = None
    for i, j in order:
        k = i * G + j
        starts = []
        if prev is not None:
            starts.append(q_out[prev])
            if i > 0 and (i - 1) * G + j != prev:
                starts.append(q_out[(i - 1) * G + j])
        starts.extend(sq[k] for sq in slice_anchor_q)
        if prev is None and q_first is not None:
            starts.append(q_first)

        def objective(q, k=k):
            q = problem.clip(q)
            value = -problem.overlap(q, k)
            if holdable:
                value += PENALTY * max(0.0, problem.effort(q, k) - HOLD_MARGIN)
            return value

        best = None
        for x0 in starts:
            result = minimize(objective, np.array(x0, dtype=float), method="Nelder-Mead",
                              options={"maxfev": maxfev, "xatol": 1e-6, "fatol": 1e-8})
            if best is None or result.fun < best.fun:
                best = result
        q_out[k] = wrap_q(problem.clip(best.x))
        n_starts[k] = len(starts)
        prev = k
    return q_out, n_starts


def covered(overlaps: np.ndarray, efforts: np.ndarray, holdable: bool) -> np.ndarray:
    ok = overlaps > COVERAGE_THRESHOLD
    return ok & (efforts <= 1.0) if holdable else ok


def cross_metrics(qa: np.ndarray, qb: np.ndarray) -> dict:
    d = wrapdiff(qa, qb, scale_l0=False)
    angle_jump = np.max(np.abs(d[:, ANGLES]), axis=1)
    scaled = np.maximum(angle_jump, np.abs(d[:, 0]) * L0_SCALE)
    return {"angle_share_gt_0.5": float(np.mean(angle_jump > SMOOTH_LIMIT)),
            "scaled_share_gt_0.5": float(np.mean(scaled > SMOOTH_LIMIT)),
            "angle_median_rad": float(np.median(angle_jump)), "angle_p90_rad": float(np.percentile(angle_jump, 90))}


def load_slices(out: Path, lengths, rolls) -> dict:
    done = {}
    for k, L in enumerate(lengths):
        for m in range(len(rolls)):
            path = slice_path(out, L, m)
            if path.exists():
                done[(k, m)] = dict(np.load(path))
    return done


def write_json(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2))
    os.replace(tmp, path)


def summarise(out: Path, args, axis, lengths, rolls, done: dict, order, run_info: dict) -> dict:
    G = args.grid
    pairs = neighbour_pairs(G)
    per_slice = []
    all_or, all_cov, in_jumps = [], [], []
    for k, m in order:
        if (k, m) not in done:
            continue
        s = done[(k, m)]
        q, ov, eff = s["q"], s["overlap"], s["effort"]
        cov = covered(ov, eff, args.holdable)
        met = metrics(q, ov, eff if args.holdable else np.zeros_like(eff), pairs)
        d = wrapdiff(q[pairs[:, 0]], q[pairs[:, 1]], scale_l0=False)
        in_jumps.append(np.max(np.abs(d[:, ANGLES]), axis=1))
        all_or.append(ov)
        all_cov.append(cov)
        per_slice.append({"L": float(lengths[k]), "roll_index": m, "roll": float(rolls[m]),
                          "coverage_percent": float(np.mean(cov) * 100), "coverage_or_only_percent":
                          float(np.mean(ov > COVERAGE_THRESHOLD) * 100), "mean_or": float(np.mean(ov)),
                          "holdable_percent": float(np.mean(eff <= 1.0) * 100),
                          "smooth_angle_share_gt_0.5": met["smooth_angle_share_gt_0.5"],
                          "smooth_scaled_share_gt_0.5": met["smooth_scaled_share_gt_0.5"],
                          "physical_share_gt_0.5": met["physical_share_gt_0.5"],
                          "smooth_angle_median_rad": met["smooth_angle_median_rad"],
                          "smooth_angle_p90_rad": met["smooth_angle_p90_rad"],
                          "share_gt_0.5_per_joint": met["share_gt_0.5_per_joint"],
                          "wall_s": float(s["wall_s"]), "mean_starts": float(np.mean(s["n_starts"])),
                          "parent": s["parent"].tolist()})
    cross = {"L": {}, "roll": {}}
    cross_all = {"L": [], "roll": []}
    for (k, m) in done:
        for kind, nb in (("L", (k + 1, m)), ("roll", (k, m + 1))):
            if nb in done:
                cm = cross_metrics(done[(k, m)]["q"], done[nb]["q"])
                cross[kind][f"L{lengths[k]:.3f}_r{m}-L{lengths[nb[0]]:.3f}_r{nb[1]}"] = cm
                cross_all[kind].append(cm["angle_share_gt_0.5"])
    summary = {
        "grid": G, "lengths": lengths.tolist(), "rolls": rolls.tolist(), "holdable": args.holdable,
        "maxfev": args.maxfev, "slice_anchors": args.slice_anchors, "n_slices_total": len(order),
        "n_slices_done": len(done), "order": [list(o) for o in order],
        "overall": {
            "coverage_percent": float(np.mean(np.concatenate(all_cov)) * 100) if all_cov else None,
            "mean_or": float(np.mean(np.concatenate(all_or))) if all_or else None,
            "in_slice_angle_share_gt_0.5": float(np.mean(np.concatenate(in_jumps) > SMOOTH_LIMIT)) if in_jumps else None,
            "across_L_angle_share_gt_0.5_mean": float(np.mean(cross_all["L"])) if cross_all["L"] else None,
            "across_roll_angle_share_gt_0.5_mean": float(np.mean(cross_all["roll"])) if cross_all["roll"] else None,
        },
        "slices": per_slice, "across_slices": cross,
        "wall_s": {"slices_total": float(sum(p["wall_s"] for p in per_slice)),
                   "per_slice_mean": float(np.mean([p["wall_s"] for p in per_slice])) if per_slice else None,
                   **run_info},
    }
    check_path = out / "check.json"
    if check_path.exists():
        summary["check"] = json.loads(check_path.read_text())
    write_json(out / "summary.json", summary)
    return summary


def run_check(out: Path, args, axis, lengths, rolls, done: dict) -> dict:
    """Independent view_tracking_optimum on check_n seeded random grid targets of the finished slices."""
    G = args.grid
    keys = sorted(done)
    n_all = len(keys) * G * G
    rng = np.random.default_rng(args.check_seed)
    pick = np.sort(rng.choice(n_all, size=min(args.check_n, n_all), replace=False))
    targets = np.array([done[keys[p // (G * G)]]["targets"][p % (G * G)] for p in pick])
    or_cont = np.array([done[keys[p // (G * G)]]["overlap"][p % (G * G)] for p in pick])
    cache = out / "check_independent.npz"
    if cache.exists() and np.array_equal(np.load(cache)["targets"], targets):
        data = np.load(cache)
        or_ind, wall = data["overlap"], float(data["wall_s"])
    else:
        started = time.perf_counter()
        optimum = view_tracking_optimum(targets, effort="standard", workers=1, progress=False)
        wall = time.perf_counter() - started
        or_ind = optimum["overlap"]
        np.savez(cache, targets=targets, overlap=or_ind, q=optimum["q"], wall_s=wall)
    result = {
        "n": int(len(pick)), "seed": args.check_seed, "slices_sampled": len(keys),
        "share_cont_losing_gt_0.02_or": float(np.mean(or_cont < or_ind - LOSS_TOLERANCE)),
        "share_cont_gaining_gt_0.02_or": float(np.mean(or_cont > or_ind + LOSS_TOLERANCE)),
        "coverage_continuation_percent": float(np.mean(or_cont > COVERAGE_THRESHOLD) * 100),
        "coverage_independent_percent": float(np.mean(or_ind > COVERAGE_THRESHOLD) * 100),
        "mean_or_continuation": float(np.mean(or_cont)), "mean_or_independent": float(np.mean(or_ind)),
        "mean_or_change": float(np.mean(or_cont - or_ind)), "independent_wall_s": wall,
        "note": "coverage here is OR > 0.8 only (the independent optimum is not made holdable)",
    }
    write_json(out / "check.json", result)
    print("check:", json.dumps(result), flush=True)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grid", type=int, default=40, help="yaw/pitch points per axis (offset axis)")
    parser.add_argument("--n-length", type=int, default=7)
    parser.add_argument("--length-min", type=float, default=0.05)
    parser.add_argument("--length-max", type=float, default=0.08)
    parser.add_argument("--n-roll", type=int, default=8)
    parser.add_argument("--roll-min", type=float, default=-math.pi / 4)
    parser.add_argument("--roll-max", type=float, default=math.pi / 4)
    parser.add_argument("--holdable", action="store_true", help="add the hold-effort penalty (residual scale 3)")
    parser.add_argument("--slice-anchors", default="all", choices=["all", "parent"],
                        help="start from every already-solved neighbouring slice, or only the parent slice")
    parser.add_argument("--maxfev", type=int, default=1500, help="Nelder-Mead evaluations per start")
    parser.add_argument("--max-slices", type=int, default=None, help="stop after computing this many new slices")
    parser.add_argument("--check", action="store_true", help="only run the sparse quality check on finished slices")
    parser.add_argument("--no-check", action="store_true", help="skip the check after the last slice")
    parser.add_argument("--check-n", type=int, default=200)
    parser.add_argument("--check-seed", type=int, default=0)
    parser.add_argument("--out", default="/work/campaigns/optimum/c11/smooth4d")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    G = args.grid
    axis, lengths, rolls = grid_axes(args)
    order, parent = slice_order(lengths, rolls)
    settings = {"grid": G, "holdable": args.holdable, "maxfev": args.maxfev, "slice_anchors": args.slice_anchors,
                "lengths": lengths.round(9).tolist(), "rolls": rolls.round(9).tolist()}
    settings_path = out / "settings.json"
    if settings_path.exists():
        old = json.loads(settings_path.read_text())
        if old != settings:
            raise SystemExit(f"{out} holds a run with other settings: {old} (now {settings})")
    else:
        write_json(settings_path, settings)
    done = load_slices(out, lengths, rolls)
    info_path = out / "run_info.json"
    run_info = json.loads(info_path.read_text()) if info_path.exists() else {"first_optimum_s": 0.0, "check_s": 0.0}
    run_info.setdefault("process_wall_s", [])
    if args.check:
        started = time.perf_counter()
        run_check(out, args, axis, lengths, rolls, done)
        run_info["check_s"] = time.perf_counter() - started
        write_json(info_path, run_info)
        summarise(out, args, axis, lengths, rolls, done, order, run_info)
        return
    print(f"{len(done)}/{len(order)} slices already done in {out}", flush=True)
    process_start = time.perf_counter()
    computed = 0
    for k, m in order:
        if (k, m) in done:
            continue
        if args.max_slices is not None and computed >= args.max_slices:
            break
        started = time.perf_counter()
        targets, _ = offset_targets(args.grid, lengths[k], rolls[m])
        problem = Problem(targets)
        if args.slice_anchors == "parent":
            neighbours = [parent[(k, m)]] if parent[(k, m)] is not None else []
        else:
            neighbours = [nb for nb in ((k - 1, m), (k + 1, m), (k, m - 1), (k, m + 1)) if nb in done]
        missing = [nb for nb in neighbours if nb not in done]
        assert not missing, f"slice {(k, m)}: neighbour slices {missing} not solved"
        q_first = None
        if parent[(k, m)] is None:
            t0 = time.perf_counter()
            q_first = view_tracking_optimum(targets[:1], effort="standard", workers=1, progress=False)["q"][0]
            run_info["first_optimum_s"] = time.perf_counter() - t0
        q, n_starts = solve_slice(problem, G, [done[nb]["q"] for nb in neighbours], q_first, args.holdable,
                                  args.maxfev)
        overlaps, efforts = evaluate(problem, q)
        wall = time.perf_counter() - started
        record = {"targets": targets, "q": q, "overlap": overlaps, "effort": efforts, "wall_s": wall,
                  "n_starts": n_starts, "L": lengths[k], "roll": rolls[m], "l_index": k, "roll_index": m,
                  "parent": np.array(parent[(k, m)] if parent[(k, m)] is not None else (-1, -1)),
                  "anchor_slices": np.array(neighbours).reshape(-1, 2), "holdable": args.holdable,
                  "maxfev": args.maxfev}
        path = slice_path(out, lengths[k], m)
        tmp = path.with_name(path.stem + ".tmp.npz")
        np.savez(tmp, **record)
        os.replace(tmp, path)
        done[(k, m)] = dict(np.load(path))
        computed += 1
        cov = covered(overlaps, efforts, args.holdable)
        pairs = neighbour_pairs(G)
        d = wrapdiff(q[pairs[:, 0]], q[pairs[:, 1]], scale_l0=False)
        jump = np.mean(np.max(np.abs(d[:, ANGLES]), axis=1) > SMOOTH_LIMIT)
        print(f"slice {len(done)}/{len(order)} L={lengths[k]:.3f} roll[{m}]={rolls[m]:+.4f}: {wall:.1f} s, "
              f"coverage {np.mean(cov) * 100:.2f} %, mean OR {np.mean(overlaps):.4f}, in-slice jumps>0.5 "
              f"{jump * 100:.2f} %, anchors {neighbours}", flush=True)
        summarise(out, args, axis, lengths, rolls, done, order, run_info)
    run_info["process_wall_s"].append(time.perf_counter() - process_start)
    write_json(info_path, run_info)
    if len(done) == len(order) and not args.no_check:
        started = time.perf_counter()
        run_check(out, args, axis, lengths, rolls, done)
        run_info["check_s"] = time.perf_counter() - started
        write_json(info_path, run_info)
    summary = summarise(out, args, axis, lengths, rolls, done, order, run_info)
    print(json.dumps(summary["overall"]), json.dumps(summary["wall_s"]), flush=True)


if __name__ == "__main__":
    main()

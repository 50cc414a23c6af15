"""Issue 38, Campaign 11: a network fitted to the 4-D continuation labels, scored on validation targets.

Fits the MLP of ``vt_label_fit.py`` (same smooth encoding of the configuration) to ``vt_smooth_labels_4d.py``'s
slices, inputs (insertion, yaw, pitch, roll) scaled to about [-1, 1], minibatch Adam; then scores the predicted
configuration on validation ``pan_tilt`` and ``static`` targets (the OR of the configuration itself, with and
without a local ascent from it) next to the offline optimum of a sample of them.

    PYTHONPATH=.:experiments/optimum python experiments/optimum/vt_label_fit_4d.py ~/campaigns/optimum/c11/smooth4d
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from vt_label_fit import fit_mlp, local_ascent, score

from continuum_gym.envs.view_tracking.distilled import decode, encode
from continuum_gym.envs.view_tracking.distilled import network_inputs as inputs

VIEW = "ContinuumGym/ViewTracking-v0"


def main(argv: list[str] | None = None) -> int:
    import torch

    from continuum_gym.envs.view_tracking.tasks import view_tasks
    from continuum_gym.evaluation.optimum.view import view_tracking_optimum
    from continuum_gym.evaluation.rollout import make_core
    from continuum_gym.robots import ContinuumEndoscope

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("slices", type=Path, help="vt_smooth_labels_4d.py's --out directory")
    parser.add_argument("--count", type=int, default=1024, help="validation ids 0..count-1 of each task")
    parser.add_argument("--optimum-count", type=int, default=256, help="of those, ids with the offline optimum")
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--batch", type=int, default=2048)
    parser.add_argument("--width", type=int, default=256, help="hidden units per layer (two tanh layers)")
    parser.add_argument("--local-fev", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="JSON summary")
    parser.add_argument("--save", type=Path, default=None, help="the fitted weights (npz: W0, b0, W1, b1, W2, b2)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)

    files = sorted(args.slices.glob("slice_*.npz"))
    if not files:
        raise SystemExit(f"no slice_*.npz in {args.slices}")
    slices = [np.load(f) for f in files]
    targets = np.concatenate([s["targets"] for s in slices])
    q = np.concatenate([s["q"] for s in slices])
    lower, upper = (np.asarray(b, dtype=float) for b in ContinuumEndoscope().joint_limits)
    net = fit_mlp(inputs(targets), encode(q), args.steps, args.seed, args.batch, args.width)
    summary: dict = {"slices": len(files), "labels": len(q),
                     "fit_rms": float(np.sqrt(np.mean((net(inputs(targets)) - encode(q)) ** 2)))}
    if args.save is not None:
        layers = [m for m in net.net if isinstance(m, torch.nn.Linear)]
        np.savez(args.save, **{f"{kind}{k}": getattr(m, name).detach().numpy().astype(np.float64)
                               for k, m in enumerate(layers) for kind, name in (("W", "weight"), ("b", "bias"))})
    context = make_core(VIEW, 1, task="pan_tilt", task_split="validation").task_context
    for task in ("pan_tilt", "static"):
        val = view_tasks(task, "validation", np.arange(args.count), context).centre
        q_net = decode(net(inputs(val)), lower, upper)
        k = args.optimum_count
        summary[task] = {"ids": f"validation 0-{args.count - 1}", "network": score(q_net, val)}
        if args.local_fev > 0:
            summary[task]["network_local"] = score(local_ascent(q_net, val, args.local_fev), val)
        if k > 0:
            optimum = view_tracking_optimum(val[:k], effort="standard", workers=1, baselines=False)["overlap"]
            summary[task][f"network_first_{k}"] = score(q_net[:k], val[:k])
            summary[task][f"optimum_first_{k}"] = {"coverage_or_only": float(100 * np.mean(optimum > 0.8)),
                                                   "mean_or": float(np.mean(optimum))}
        print(task, json.dumps(summary[task]), flush=True)
    if args.out is not None:
        args.out.write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Issue 38, Campaign 11: can a network learn the ViewTracking optimum as a function of the target?

Fits an MLP (yaw, pitch) -> configuration to the label sets of ``vt_smooth_labels.py`` (the offset-grid
training targets) and scores the fitted map on held-out validation ``pan_tilt`` targets: the overlap ratio of
the predicted configuration, its hold effort at residual scale 3 and the coverage (OR > 0.8 and effort <= 1).
The configuration is encoded smoothly where it matters: phi as (cos, sin), each segment's bend as the vector
theta (cos delta, sin delta), so that a label that differs only in an angle of a straight segment is the same
point. A 1-nearest-neighbour lookup is scored next to the network. The behaviour cloning of the earlier
campaigns failed on the independent labels (neighbouring targets had unrelated configurations); this measures
whether continuation labels fix that.

    PYTHONPATH=. python experiments/optimum/vt_label_fit.py /work/campaigns/optimum/c11/smooth/labels_G40_standard.npz
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from continuum_gym.envs.view_tracking.distilled import decode, encode  # the encoding the shipped network uses

VIEW = "ContinuumGym/ViewTracking-v0"


def fit_mlp(x: np.ndarray, y: np.ndarray, steps: int, seed: int, batch: int | None = None, width: int = 256):
    """Two tanh layers of ``width``, Adam (lr 1e-3, cosine to 0) on the mean squared error; full batch, or
    ``batch`` rows drawn (seeded) per step. Returns the fitted map as a numpy function."""
    import torch

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], width), torch.nn.Tanh(), torch.nn.Linear(width, width),
                              torch.nn.Tanh(), torch.nn.Linear(width, y.shape[1]))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    X, Y = torch.tensor(x, dtype=torch.float32), torch.tensor(y, dtype=torch.float32)
    for _ in range(steps):
        rows = slice(None) if batch is None else torch.as_tensor(rng.integers(0, len(x), batch))
        opt.zero_grad()
        loss = torch.mean((net(X[rows]) - Y[rows]) ** 2)
        loss.backward()
        opt.step()
        sched.step()
    fitted = lambda inputs: net(torch.tensor(inputs, dtype=torch.float32)).detach().numpy().astype(float)  # noqa: E731
    fitted.net = net  # the torch module, for saving its weights
    return fitted


def score(q: np.ndarray, targets: np.ndarray) -> dict:
    from residual_reach import hold_effort

    from continuum_gym.evaluation.optimum.view import overlap_of_configuration
    from continuum_gym.geometry.frustum import Frustum
    from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

    frustum, robot = Frustum(), ContinuumEndoscope().kernel_args()
    p_a, R_a = DaVinciEndoscope().forward_kinematics(targets)
    overlap = np.array([overlap_of_configuration(np.ascontiguousarray(q[k]), p_a[k], R_a[k], robot, frustum.tan_half,
                                                 frustum.near, frustum.far) for k in range(len(q))])
    effort = hold_effort(q, targets, 3.0)
    return {"coverage": float(100 * np.mean((overlap > 0.8) & (effort <= 1.0))),
            "coverage_or_only": float(100 * np.mean(overlap > 0.8)), "mean_or": float(np.mean(overlap)),
            "holdable": float(100 * np.mean(effort <= 1.0))}


def local_ascent(q: np.ndarray, targets: np.ndarray, maxfev: int) -> np.ndarray:
    """Nelder-Mead on -OR from each configuration, ``maxfev`` evaluations each: what a local residual on top of
    the fitted map could reach at most (it does not see the hold effort)."""
    from scipy.optimize import minimize

    from continuum_gym.evaluation.optimum.view import overlap_of_configuration
    from continuum_gym.geometry.frustum import Frustum
    from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

    frustum, endoscope = Frustum(), ContinuumEndoscope()
    robot, (lower, upper) = endoscope.kernel_args(), endoscope.joint_limits
    p_a, R_a = DaVinciEndoscope().forward_kinematics(targets)
    out = np.array(q, dtype=float)
    for k in range(len(q)):
        def objective(x, k=k):
            x = np.ascontiguousarray(np.clip(x, lower, upper))
            return -overlap_of_configuration(x, p_a[k], R_a[k], robot, frustum.tan_half, frustum.near, frustum.far)

        out[k] = np.clip(minimize(objective, q[k], method="Nelder-Mead", options={"maxfev": maxfev}).x, lower, upper)
    return out


def main(argv: list[str] | None = None) -> int:
    from continuum_gym.envs.view_tracking.tasks import view_tasks
    from continuum_gym.evaluation.rollout import make_core
    from continuum_gym.robots import ContinuumEndoscope

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("labels", type=Path, help="vt_smooth_labels.py's labels_*.npz")
    parser.add_argument("--count", type=int, default=1024, help="validation pan_tilt ids 0..count-1")
    parser.add_argument("--steps", type=int, default=4000, help="full-batch Adam steps")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="JSON summary")
    parser.add_argument("--local-fev", type=int, default=0,
                        help="also score a local Nelder-Mead ascent of OR from the network's configurations")
    args = parser.parse_args(argv)

    data = np.load(args.labels)
    train_targets = data["targets"]
    core = make_core(VIEW, 1, task="pan_tilt", task_split="validation")
    val_targets = view_tasks("pan_tilt", "validation", np.arange(args.count), core.task_context).centre
    lower, upper = (np.asarray(b, dtype=float) for b in ContinuumEndoscope().joint_limits)
    x_train = train_targets[:, 1:3] / (math.pi / 3)
    x_val = val_targets[:, 1:3] / (math.pi / 3)
    summary: dict = {"labels": str(args.labels), "validation_ids": f"pan_tilt 0-{args.count - 1}"}
    for name in [k[2:] for k in data.files if k.startswith("q_")]:
        y = encode(data[f"q_{name}"])
        net = fit_mlp(x_train, y, args.steps, args.seed)
        nearest = np.argmin(np.sum((x_val[:, None, :] - x_train[None, :, :]) ** 2, axis=2), axis=1)
        covered = (data[f"or_{name}"] > 0.8) & (data[f"effort_{name}"] <= 1)
        summary[name] = {"labels_on_grid": float(100 * np.mean(covered)),
                         "fit_rms": float(np.sqrt(np.mean((net(x_train) - y) ** 2))),
                         "mlp_on_grid": score(decode(net(x_train), lower, upper), train_targets),
                         "mlp_validation": score(decode(net(x_val), lower, upper), val_targets),
                         "nearest_validation": score(data[f"q_{name}"][nearest], val_targets)}
        if args.local_fev > 0:
            q_local = local_ascent(decode(net(x_val), lower, upper), val_targets, args.local_fev)
            summary[name]["mlp_validation_local"] = score(q_local, val_targets)
        print(name, json.dumps(summary[name]), flush=True)
    if args.out is not None:
        args.out.write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Issue 38, Campaign 12: the ViewTracking base that steers to a distilled smooth optimum, as a plug-in.

Registers ``distilled_optimum``: the package's controller (``continuum_gym.envs.view_tracking.distilled``, which says
what it does) with the weights named by ``VT_DISTILLED_NET`` (default: the package's) and the gain and rate cap
of ``VT_DISTILLED_GAIN`` / ``VT_DISTILLED_CAP`` (default the package's 40 1/s and 10 action units), so that
``continuum-gym --import vt_distilled train/evaluate`` and the campaign scripts take other fits. Run as a
script it scores the base alone (zero residual) on validation tasks:

    PYTHONPATH=.:experiments/optimum python experiments/optimum/vt_distilled.py --count 1024 [--polish 0.05]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

VIEW = "ContinuumGym/ViewTracking-v0"
NAME = "distilled_optimum"


def register(gain: float | None = None, cap: float | None = None, ascent: float | None = None) -> None:
    """The package's controller (``continuum_gym.envs.view_tracking.distilled``) with ``VT_DISTILLED_NET``'s weights;
    without its OR lookahead unless ``VT_DISTILLED_ASCENT`` says (Campaign 12's runs (a), (a2) trained on that)."""
    from continuum_gym.envs.view_tracking.distilled import CAP, GAIN, WEIGHTS
    from continuum_gym.envs.view_tracking.distilled import register as register_distilled

    gain = float(os.environ.get("VT_DISTILLED_GAIN", GAIN)) if gain is None else gain
    cap = float(os.environ.get("VT_DISTILLED_CAP", CAP)) if cap is None else cap
    ascent = float(os.environ.get("VT_DISTILLED_ASCENT", 0.0)) if ascent is None else ascent
    register_distilled(Path(os.environ.get("VT_DISTILLED_NET", WEIGHTS)), gain, cap, ascent, NAME)


register()


def main(argv: list[str] | None = None) -> int:
    from val_eval import rollout

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1024, help="validation ids 0..count-1 of pan_tilt and static")
    parser.add_argument("--polish", type=float, default=None, help="overlap_polish (None: off)")
    parser.add_argument("--gain", type=float, default=40.0, help="1/s")
    parser.add_argument("--cap", type=float, default=10.0, help="rate cap per joint, in action units")
    parser.add_argument("--tasks", nargs="+", default=["pan_tilt", "static", "random"])
    args = parser.parse_args(argv)
    register(gain=args.gain, cap=args.cap)
    kwargs = {"base_controller": NAME, "residual_scale": 3.0, "overlap_polish": args.polish}
    for task in args.tasks:
        out = rollout(VIEW, None, kwargs, task, args.count if task != "random" else min(args.count, 256))
        summary = {"mean_or": float(np.mean(out["mean_or"])), "coverage": float(100 * np.mean(out["final_or"] > 0.8))}
        print(task, json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

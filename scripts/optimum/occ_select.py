"""Checkpoint selection for OcclusionAvoidance runs on validation hold ids disjoint from the reported ones.

Issue 38, Campaign 3 (docs/optimum-experiments.md). For each run directory, every kept checkpoint
(``checkpoints/step_<n>/model.zip``) and the final ``model.zip`` are scored on validation **hold ids 32-63**
(mean hold VOI, deterministic policy, the run's policy keywords, as ``val_eval.py`` does); the reported
validation figures use hold ids 0-31 and random ids 0-31, so the choice is not made on the ids it is reported
on. The selected model (lowest selection hold VOI) is then scored on the reported ids with ``val_eval.py``'s
``measure`` and appended to ``<root>/results/val_occ.jsonl`` with tag ``<tag>_sel`` (``step`` null, the
selected step in ``selected_step``); every selection score goes to ``<root>/results/val_occ_selection.jsonl``.

    python scripts/optimum/occ_select.py --tag occ_s2 ~/campaigns/optimum/runs/occ_s2/*seed*
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import val_eval  # noqa: E402

SELECT = ("hold", 32, 32)  # task, count, first id


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--tag", required=True)
    parser.add_argument("--min-step", type=int, default=0, help="ignore checkpoints before this step")
    parser.add_argument("--root", type=Path, default=val_eval.ROOT)
    args = parser.parse_args(argv)
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.evaluate import policy_env_kwargs

    task, count, first = SELECT
    for run in args.runs:
        run = run.expanduser().resolve()
        targets = sorted(run.glob("checkpoints/step_*/model.zip")) + [run]
        scores = []
        for target in targets:
            model, config, _, step = val_eval.load(target)
            if step is not None and step < args.min_step:
                continue
            kwargs = policy_env_kwargs(get_spec(config["env_id"]), config)
            per = val_eval.rollout(config["env_id"], model, kwargs, task, count, first)
            hold = float(np.mean(per["mean_voi"]))
            in_view = float(np.min(per["tip_in_view_fraction"]))
            label = step if step is not None else "final"
            scores.append((hold, label, target, model, kwargs, config["env_id"]))
            with open(args.root / "results" / "val_occ_selection.jsonl", "a") as f:
                f.write(json.dumps({"tag": args.tag, "run": str(run), "step": step, "selection_hold_voi": hold,
                                    "selection_tip_in_view_min": in_view,
                                    "selection_ids": f"{task} {first}-{first + count - 1}"}) + "\n")
            print(f"{run.name} {label}: selection hold VOI {hold:.4f} (min in view {in_view:.3f})", flush=True)
        hold, label, target, model, kwargs, env_id = min(scores, key=lambda s: s[0])
        start = time.time()
        summary, arrays = val_eval.measure(env_id, model, kwargs)
        ref = val_eval.occ_reference(args.root)
        summary["headroom"] = (ref["base_hold_voi"] - summary["hold_voi"]) / (ref["base_hold_voi"] -
                                                                              ref["optimum_hold_voi"])
        seed = re.search(r"seed(\d+)$", run.name)
        record = {"tag": f"{args.tag}_sel", "env_id": env_id, "split": val_eval.SPLIT, "run": str(run),
                  "seed": int(seed.group(1)) if seed else None, "step": None,
                  "selected_step": None if label == "final" else label, "selection_hold_voi": hold, **summary,
                  "base_hold_voi": ref["base_hold_voi"], "optimum_hold_voi": ref["optimum_hold_voi"],
                  "eval_s": round(time.time() - start, 1), "at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        with open(args.root / "results" / "val_occ.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        np.savez(args.root / "results" / "arrays" / f"{args.tag}_sel_{run.name}.npz", **arrays)
        print(json.dumps(record), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Resumable training queue of the issue 38 campaign (experiments/notebook.md).

Trains the runs of a queue one at a time, each as ``continuum-gym train ... --resume`` under ``nice -n 15``
with ``OMP_NUM_THREADS=1`` (one core; the trainer sets torch to one thread itself):

* a run whose ``model.zip`` exists is skipped; one with checkpoints continues from its newest intact one
  (``--resume``); one without starts at step 0;
* run directories go to ``<root>/runs/<tag>/<run name>/``, logs to ``<root>/logs/<tag>_seed<S>.log``, and each
  finished training appends ``{tag, seed, rc, cpu_s, wall_s}`` (CPU-s of the training process: user + system,
  its periodic validation curve included) to ``<root>/results/train_cpu.jsonl``;
* the file ``<root>/STOP`` halts the queue between runs (the running one finishes; delete the file and start
  the script again to go on).

The code trained is a frozen copy of the package (``--src``, used through ``PYTHONPATH``), so that edits in
the work tree during a campaign do not reach the runs: ``git archive <commit> | tar -x -C <root>/src``.
The hyperparameter files are ``experiments/optimum/<tag>.yml``.

    nohup python experiments/optimum/run_queue.py occ_ep10:0-2 vt_mix_s3_lin20m:0-2 > ~/campaigns/optimum/logs/queue.log 2>&1 &
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = Path.home() / "campaigns" / "optimum"
ENVS = {"occ": "ContinuumGym/OcclusionAvoidance-v0", "vt": "ContinuumGym/ViewTracking-v0"}


def env_of(tag: str) -> str:
    """The env id a config tag trains (``occ_*`` or ``vt_*``)."""
    return ENVS[tag.split("_")[0]]


def parse_item(item: str) -> list[tuple[str, int]]:
    """``tag:0-4`` or ``tag:0,2`` -> [(tag, seed), ...]."""
    tag, _, seeds = item.partition(":")
    out: list[int] = []
    for part in (seeds or "0").split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return [(tag, s) for s in out]


def finished(root: Path, tag: str, seed: int) -> bool:
    return any((root / "runs" / tag).glob(f"*_seed{seed}/model.zip"))


def train_one(root: Path, src: Path, tag: str, seed: int, imports: tuple[str, ...] = ()) -> dict:
    out = root / "runs" / tag
    out.mkdir(parents=True, exist_ok=True)
    plugins = [arg for module in imports for arg in ("--import", module)]
    cmd = ["nice", "-n", "15", sys.executable, "-m", "continuum_gym.cli", *plugins, "train", "--env", env_of(tag),
           "--seed", str(seed), "--hyperparams", str(HERE / f"{tag}.yml"), "--out", str(out), "--resume",
           "--no-progress"]
    # the frozen copy's experiments/optimum holds the campaign's plug-ins (vt_weighted_mix.py)
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=os.pathsep.join([str(src), str(src / "experiments" / "optimum")]))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.time()
    with open(root / "logs" / f"{tag}_seed{seed}.log", "a") as log:
        log.write(f"# {time.strftime('%Y-%m-%d %H:%M:%S')} {' '.join(cmd)}\n")
        log.flush()
        rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=str(root))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"tag": tag, "seed": seed, "rc": rc, "cpu_s": round(cpu, 1), "wall_s": round(time.time() - start, 1),
            "src": str(src), "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("items", nargs="+", help="tag:seeds, e.g. occ_ep10:0-2")
    parser.add_argument("--root", type=Path, default=ROOT, help=f"campaign directory (default {ROOT})")
    parser.add_argument("--src", type=Path, default=None, help="frozen package copy (default <root>/src)")
    parser.add_argument("--import", dest="imports", action="append", default=[], metavar="MODULE",
                        help="plug-in module for `continuum-gym --import` (from <src>/experiments/optimum), repeatable")
    args = parser.parse_args(argv)
    root, src = args.root, args.src or args.root / "src"
    for sub in ("runs", "logs", "results"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    queue = [job for item in args.items for job in parse_item(item)]
    for tag, seed in queue:
        if (root / "STOP").exists():
            print(f"{root / 'STOP'} exists: halting before {tag} seed {seed}", flush=True)
            return 0
        if finished(root, tag, seed):
            print(f"skip {tag} seed {seed}: model.zip exists", flush=True)
            continue
        print(f"{time.strftime('%H:%M:%S')} train {tag} seed {seed}", flush=True)
        record = train_one(root, src, tag, seed, tuple(args.imports))
        with open(root / "results" / "train_cpu.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        print(f"{time.strftime('%H:%M:%S')} done {json.dumps(record)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

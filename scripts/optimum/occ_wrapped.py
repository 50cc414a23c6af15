"""Issue 38, Campaign 3: OcclusionAvoidance training with progressive exploration or a hold-start curriculum.

Neither touches the env code: the script replaces ``continuum_gym.envs.sb3.ContinuumSB3VecEnv`` in its own process
by a subclass (used only for the **training** vector env; the trainer's validation curve builds its own cores) and
then calls ``continuum_gym.agents.train.train`` with ``scripts/optimum/<tag>.yml``. The saved policy and every
evaluation always have the residual on, on the unchanged env.

* ``prog`` (progressive exploration, as in "Policy Decorator"; Campaign 1's lost script re-made): each row's
  episode runs with the residual on with probability p, else its action is replaced by zero (the analytic base
  alone). p ramps linearly from ``p0`` to 1 over the first ``ramp`` env steps (summed over rows). With PPO the
  actions sampled in "off" episodes have no effect on the env (variance, no bias).
* ``cur`` (curriculum over the hold starts the baseline does worst on): the train split's 512 hold starts are
  scored once with the base alone (zero residual, the run's policy keywords); a hold episode (even task id of the
  ``mixed`` task) is then drawn with probability ``hard_prob`` from the ``hard_frac`` of starts with the highest
  base hold VOI, else as the env draws it. Random-trajectory episodes (odd ids) are untouched.

The realised settings go to ``<run>/wrapper.json``; CPU-s of the process to ``<root>/results/train_cpu.jsonl``.

    OMP_NUM_THREADS=1 PYTHONPATH=~/campaigns/optimum/src nice -n 15 python scripts/optimum/occ_wrapped.py occ_prog2 --seed 0
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = Path.home() / "campaigns" / "optimum"
ENV = "ContinuumGym/OcclusionAvoidance-v0"
#: tag -> wrapper settings (the yml of the same tag holds the PPO / env keywords).
SETTINGS = {
    "occ_prog2": {"mode": "prog", "p0": 0.2, "ramp": 300_000},
    "occ_cur": {"mode": "cur", "hard_prob": 0.5, "hard_frac": 0.25},
    "occ_ep10cur": {"mode": "cur", "hard_prob": 0.5, "hard_frac": 0.25},  # occ_ep10.yml's keys + occ_cur's curriculum
    # Campaign 4: half the hold episodes from the starts where a trained residual stays farthest above the optimum
    "occ_gap": {"mode": "gap", "hard_prob": 0.5},  # occ_s2.yml's keys
    "occ_ep10gap": {"mode": "gap", "hard_prob": 0.5},  # occ_ep10.yml's keys
}
HOLD_TRAIN = 512  # HOLD_POOL_SIZE["train"] in envs/occlusion/tasks.py


def base_hold_voi(env_kwargs: dict) -> np.ndarray:
    """Base-only (zero residual) mean VOI of each of the train split's hold starts."""
    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes

    kwargs = {k: v for k, v in env_kwargs.items() if k != "task"}
    core = make_core(ENV, 128, **dict(kwargs, task="hold", task_split="train"))
    zero = ZeroResidual(core.single_action_space.shape[0])
    out = [run_episodes(core, zero, np.arange(i, i + 128))["mean_voi"] for i in range(0, HOLD_TRAIN, 128)]
    return np.concatenate(out)


def make_class(settings: dict, record: dict):
    import continuum_gym.envs.sb3 as sb3

    parent = sb3.ContinuumSB3VecEnv

    class Wrapped(parent):
        def __init__(self, env_id, num_envs, *args, **kwargs):
            super().__init__(env_id, num_envs, *args, **kwargs)
            self._train = kwargs.get("task_split") == "train"
            self._t = 0
            self._on = np.ones(num_envs, dtype=bool)
            self._on_steps = 0
            if not self._train:
                return
            if settings["mode"] in ("cur", "gap"):
                assert self.env_kwargs.get("task") == "mixed", "the curriculum is written for task: mixed"
            if settings["mode"] == "cur":
                voi = base_hold_voi({k: v for k, v in self.env_kwargs.items()})
                n_hard = int(round(settings["hard_frac"] * len(voi)))
                self._hard = np.argsort(voi)[::-1][:n_hard]
                record.update(base_train_hold_voi_mean=float(voi.mean()),
                              hard_starts_base_voi_mean=float(voi[self._hard].mean()), n_hard=n_hard)
            if settings["mode"] == "gap":
                gap = json.loads((ROOT / "results" / "gap_hard_starts.json").read_text())
                self._hard = np.asarray(gap["hard_starts"], dtype=np.int64)
                record.update(gap_source=gap["run"], n_hard=len(self._hard), hard_gap_mean=gap["hard_gap_mean"])
            if settings["mode"] in ("cur", "gap"):
                draw = self.core.sample_task_id

                def sample(rng, _draw=draw, _hard=self._hard, _p=settings["hard_prob"]):
                    task_id = _draw(rng)
                    if task_id % 2 == 0 and rng.random() < _p:  # a hold episode: from the hard starts
                        task_id = 2 * int(_hard[rng.integers(len(_hard))])
                    return task_id

                self.core.sample_task_id = sample
            elif settings["mode"] == "prog":
                self._rng = np.random.default_rng(12345 + num_envs)
                self._on = self._rng.random(num_envs) < self._p()

        def _p(self):
            return min(1.0, settings["p0"] + (1 - settings["p0"]) * self._t / settings["ramp"])

        def step_async(self, actions):
            if self._train and settings["mode"] == "prog":
                actions = np.where(self._on[:, None], actions, 0.0).astype(np.asarray(actions).dtype)
            super().step_async(actions)

        def step_wait(self):
            obs, rewards, dones, infos = super().step_wait()
            if self._train:
                self._on_steps += int(self._on.sum())
                self._t += self.num_envs
                record["steps"] = self._t
                record["on_fraction"] = self._on_steps / self._t
                if settings["mode"] == "prog" and dones.any():
                    finished = np.flatnonzero(dones)
                    self._on[finished] = self._rng.random(len(finished)) < self._p()
            return obs, rewards, dones, infos

    sb3.ContinuumSB3VecEnv = Wrapped


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tag", choices=sorted(SETTINGS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--root", type=Path, default=ROOT)
    parser.add_argument("--steps", type=int, default=None, help="override n_timesteps (smoke tests)")
    parser.add_argument("--out", type=Path, default=None, help="default <root>/runs/<tag>")
    args = parser.parse_args(argv)
    settings = SETTINGS[args.tag]
    record: dict = {"tag": args.tag, **settings}
    make_class(settings, record)
    from continuum_gym.agents.train import train

    start = time.time()
    run = train(ENV, "ppo", seed=args.seed, hyperparams=HERE / f"{args.tag}.yml", steps=args.steps,
                out=args.out or args.root / "runs" / args.tag,
                progress=False, command=f"scripts/optimum/occ_wrapped.py {args.tag} --seed {args.seed}")
    (Path(run) / "wrapper.json").write_text(json.dumps(record, indent=1))
    usage = resource.getrusage(resource.RUSAGE_SELF)
    with open(args.root / "results" / "train_cpu.jsonl", "a") as f:
        f.write(json.dumps({"tag": args.tag, "seed": args.seed, "rc": 0, "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
                            "wall_s": round(time.time() - start, 1), "src": "occ_wrapped.py",
                            "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}) + "\n")
    print(json.dumps(record), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

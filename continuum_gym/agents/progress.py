"""The training progress bar: the run's own steps, from where it starts to the step it actually ends at.

SB3's bar counts from 0 to the steps left in *this* call of ``learn`` and ends wherever the last rollout ends,
so a run resumed from a checkpoint read, e.g., ``20,480/18,080``: PPO trains whole rollouts of
``n_steps x n_envs`` steps (an off-policy learner ``train_freq x n_envs``), which the last one rounds up. This
bar starts at the checkpoint's step and ends at the step the last whole rollout reaches.
"""

from __future__ import annotations

import math

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} steps [{elapsed}<{remaining}, {rate_fmt}]"


def rollout_steps(model: BaseAlgorithm) -> int | None:
    """Environment steps (summed over the vector env) one rollout collects; None when episodes delimit it."""
    if isinstance(model, OnPolicyAlgorithm):
        return model.n_steps * model.n_envs
    if isinstance(model, OffPolicyAlgorithm):
        frequency = model.train_freq  # a TrainFreq once learn() has set up
        if not isinstance(frequency, TrainFreq) or frequency.unit != TrainFrequencyUnit.STEP:
            return None
        return frequency.frequency * model.n_envs
    return None


def training_end(model: BaseAlgorithm, total: int) -> int:
    """The step a run at ``model.num_timesteps`` ends at when trained towards ``total`` steps: SB3 collects whole
    rollouts until it has reached ``total``, so the last one may pass it."""
    start, rollout = model.num_timesteps, rollout_steps(model)
    if rollout is None or total <= start:
        return max(total, start)
    return start + math.ceil((total - start) / rollout) * rollout


class ProgressBar(BaseCallback):
    """A tqdm bar of the run's environment steps: initial = the steps already trained (a resumed run's
    checkpoint), total = the step the run ends at (:func:`training_end`), kept at the model's own count."""

    def __init__(self, total: int, desc: str = "train") -> None:
        super().__init__()
        self.total, self.desc = int(total), desc
        self.bar = None

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        start = self.model.num_timesteps
        self.bar = tqdm(total=training_end(self.model, self.total), initial=start, desc=self.desc,
                        bar_format=BAR_FORMAT, unit="steps", unit_scale=False, dynamic_ncols=True)

    def _on_step(self) -> bool:
        if self.bar is not None:
            self.bar.update(self.model.num_timesteps - self.bar.n)
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            self.bar.close()
            self.bar = None

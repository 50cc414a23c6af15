"""What is specific to residual learners: zero-initialised output and critic burn-in.

The residual itself lives in the environment (``base_controller=...``), so SB3's buffers store the
policy's own output; here only the learner is prepared so that an untrained agent equals its base.
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

import torch
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback


def _last_linear(module: torch.nn.Module) -> torch.nn.Linear:
    layers = [m for m in module.modules() if isinstance(m, torch.nn.Linear)]
    if not layers:
        raise ValueError(f"no Linear layer in {type(module).__name__}")
    return layers[-1]


@torch.no_grad()
def zero_init_residual(model: BaseAlgorithm) -> None:
    """Make the deterministic action exactly 0 (the baseline's command) for every observation.

    PPO: the action net (mean of the Gaussian); SAC: ``actor.mu`` (tanh(0) = 0); TD3: the actor's last
    Linear (before tanh), copied into ``actor_target`` as ``td3/policies.py`` does at construction.
    """
    layers: list[torch.nn.Linear]
    if isinstance(model, PPO):
        layers = [cast(torch.nn.Linear, model.policy.action_net)]  # a Linear for Box action spaces
    elif isinstance(model, SAC):
        layers = [cast(torch.nn.Linear, model.actor.mu)]
    elif isinstance(model, TD3):
        layers = [_last_linear(model.actor.mu)]
    else:
        raise ValueError(f"residual initialisation supports PPO, SAC and TD3; got {type(model).__name__}")
    for layer in layers:
        layer.weight.zero_()
        layer.bias.zero_()
    if isinstance(model, TD3):
        model.actor_target.load_state_dict(model.actor.state_dict())


def actor_parameters(model: BaseAlgorithm) -> list[torch.nn.Parameter]:
    """The parameters that move the action (PPO: everything but the value head and log_std)."""
    if isinstance(model, PPO):
        policy = model.policy
        shared = list(policy.features_extractor.parameters()) + list(policy.mlp_extractor.policy_net.parameters())
        return shared + list(policy.action_net.parameters())
    return list(model.actor.parameters())  # type: ignore[attr-defined]  # SAC, TD3: an actor network


class ActorBurnIn(BaseCallback):
    """Keep the actor at its initial (zero-residual) weights for the first ``steps`` environment steps.

    The critic learns the baseline's values first, so the actor's first updates follow a sensible
    advantage or Q estimate instead of a random one. Restores the actor after every update until then.
    ``steps`` counts the model's ``num_timesteps``, so a resumed run continues where it stopped;
    ``snapshot`` is the initial actor to restore (default: the actor when training starts), which a
    resumed run takes from its checkpoint (``save_snapshot`` / ``load_snapshot``).
    """

    def __init__(self, steps: int, snapshot: list[torch.Tensor] | None = None, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.steps = int(steps)
        self._snapshot = snapshot

    def _on_training_start(self) -> None:
        if self._snapshot is None:
            self._snapshot = [p.detach().clone() for p in actor_parameters(self.model)]

    def save_snapshot(self, path: Path | str) -> None:
        """Write the actor being restored (taken at training start unless given)."""
        if self._snapshot is None:
            raise RuntimeError("ActorBurnIn has no snapshot before training starts")
        torch.save([tensor.cpu() for tensor in self._snapshot], path)

    @staticmethod
    def load_snapshot(path: Path | str) -> list[torch.Tensor]:
        return torch.load(path, weights_only=True)

    @torch.no_grad()
    def _restore(self) -> None:
        # model.num_timesteps, not self.num_timesteps: the callback's copy is only refreshed in on_step,
        # so at the first rollout start of a resumed run it would still read 0.
        if self._snapshot is not None and self.model.num_timesteps <= self.steps:
            for param, saved in zip(actor_parameters(self.model), self._snapshot):
                param.copy_(saved)
            if isinstance(self.model, TD3):
                self.model.actor_target.load_state_dict(self.model.actor.state_dict())

    def _on_rollout_start(self) -> None:
        self._restore()

    def _on_step(self) -> bool:
        if self.model.num_timesteps <= self.steps and not isinstance(self.model, PPO):
            self._restore()
        return True

"""Evaluation: any policy against the analytic baselines and the offline optimum (``evaluate_policy``)."""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    # Lazy, so that ``continuum-gym <command> --help`` does not import the evaluation stack.
    if name == "evaluate_policy":
        from continuum_gym.evaluation.evaluate import evaluate_policy

        return evaluate_policy
    raise AttributeError(f"module 'continuum_gym.evaluation' has no attribute {name!r}")


__all__ = ["evaluate_policy"]

"""SIGKILL fault injection on real training subprocesses (PPO and SAC): the short version of
``benchmarks/fault_injection.py`` (which runs 20 kills per algorithm; figures in the README).

Per algorithm: one kill at a random moment and one inside a checkpoint write (all files staged, the
atomic rename not yet done); each run is resumed to the full step count with verified checkpoints, a
strictly increasing evaluation history, and, if it restarted from zero, the reference's exact model.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

HARNESS = Path(__file__).resolve().parents[2] / "benchmarks" / "fault_injection.py"


@pytest.fixture(scope="module")
def harness():
    spec = importlib.util.spec_from_file_location("fault_injection", HARNESS)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_killed_runs_resume_complete_and_consistent(harness, algo, tmp_path):
    report_path = tmp_path / "report.json"
    assert harness.main(["--kills", "2", "--algos", algo, "--seed", "3", "--json", str(report_path)]) == 0
    report = json.loads(report_path.read_text())[algo]
    assert report["complete_and_consistent"] == 2
    assert report["inside_write"] == 1  # the odd trial died with a staged, unpublished unit
    for row in report["trials"]:
        if row["restarted_from_zero"]:
            assert row["equal"]

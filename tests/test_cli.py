"""The console script: every command's --help answers from argparse alone, without the numerical stack."""

from __future__ import annotations

import subprocess
import sys

import pytest

from continuum_gym.cli import SUBCOMMANDS

HEAVY = ("numba", "torch", "pybullet", "matplotlib", "stable_baselines3", "scipy", "ray", "continuum_gym.robots",
         "continuum_gym.baselines", "continuum_gym.geometry")


@pytest.mark.parametrize("command", sorted(SUBCOMMANDS))
def test_help_imports_nothing_heavy(command):
    """What makes `--help` take seconds is importing compiled kernels, torch or pybullet: none may load."""
    code = (f"import sys\nfrom continuum_gym.cli import main\ntry:\n    main([{command!r}, '--help'])\n"
            f"except SystemExit:\n    pass\nprint('HEAVY:' + ','.join(m for m in {HEAVY!r} if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "usage: continuum-gym" in result.stdout
    loaded = result.stdout.rsplit("HEAVY:", 1)[1].strip()
    assert loaded == "", f"continuum-gym {command} --help imported {loaded}"


@pytest.mark.parametrize("command", ["train", "evaluate", "render", "dataset", "optimum", "sweep", "precompile"])
def test_an_unknown_env_id_tells_how_to_register_ones_own(command, capsys, tmp_path):
    """Every command that takes --env says that a user's id is registered at import of a module, and how."""
    from continuum_gym.cli import main
    from continuum_gym.plugins import ENTRY_POINT_GROUP, ENV_VAR

    out = tmp_path / "out"
    where = {"dataset": ["--root", str(out)], "precompile": []}.get(command, ["--out", str(out)])
    assert main([command, "--env", "MyLab/Occlusion4Seg-v0", *where]) == 2
    err = capsys.readouterr().err
    assert "unknown env id 'MyLab/Occlusion4Seg-v0'" in err
    for needle in ("registered at import of", "continuum-gym --import MODULE", ENTRY_POINT_GROUP, f"{ENV_VAR}=MODULE"):
        assert needle in err, needle
    assert not out.exists()

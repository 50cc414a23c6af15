"""``continuum-gym demo``: the figure is written; the printed tip poses are the kinematics' own, explained, once."""

from __future__ import annotations

import re

import numpy as np
from PIL import Image

from continuum_gym.cli import main
from continuum_gym.robots import MultiBackboneRobot, rotation_vector


def test_demo_draws_the_figure_and_prints_true_tip_poses(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    check_printed_once_and_explained(printed.splitlines(), tmp_path)
    with Image.open(tmp_path / "demo.png") as image:
        assert image.size[0] >= 1200 and image.size[1] >= 900
        assert len(np.unique(np.asarray(image.convert("L")))) > 50  # drawn, not blank
    line = next(line for line in printed.splitlines() if "MBCR start psi_a" in line)
    numbers = [float(x) for x in re.findall(r"-?\d+\.\d+", line)]
    robot = MultiBackboneRobot()
    p, R = robot.forward_kinematics(robot.psi_a)
    np.testing.assert_allclose(numbers[:3], p * 1e3, atol=1e-3)  # printed in mm, 3 decimals
    np.testing.assert_allclose(numbers[3:6], rotation_vector(R), atol=1e-4)
    assert sum("endoscope case" in line for line in printed.splitlines()) == 4  # 2 cases x 2 controllers


def check_printed_once_and_explained(lines, out):
    """Each line once; a header that says what the poses are, in which frame and units; aligned columns."""
    assert len(lines) == len(set(lines))
    header, poses = lines[0], [line for line in lines if " p = [" in line]
    assert header.startswith("Tip poses") and all(word in header for word in ("world frame", "mm", "rad"))
    assert "{" not in header  # the papers' frame names ({w}) do not explain themselves
    assert len(poses) == len(lines) - 2  # the header, the poses, the figure's path
    assert len({line.index(" p = [") for line in poses}) == 1  # one column per quantity, however long the name
    assert lines[-1] == f"wrote {out / 'demo.png'}"

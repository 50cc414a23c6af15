"""Render the pictures of the README and the environment pages with ``continuum-gym render``.

    python scripts/render_docs_images.py [--out docs/img]

Writes to ``--out`` (about 45 s on 2 cores):

- ``occlusion-avoidance.gif``: OcclusionAvoidance-v0, task circle, the projected-gradient baseline, the
  whole 10 s episode at 10 frames/s: outside view (robot, endoscope shaft, yellow view cone, tissue)
  beside what the endoscope sees;
- ``view-tracking.gif``: ViewTracking-v0, task case1, the dimension-reduced-IK baseline, the first 4 s
  at 20 frames/s: outside view (continuum endoscope, da Vinci stem, green and blue view frustums)
  beside the continuum endoscope's and the da Vinci endoscope's images;
- ``hero.png``: one still of each, stacked (the README's first picture).

Every picture is one ``continuum-gym render`` command (``COMMANDS``); only the hero's two stills are
stacked here. The commands run with this interpreter (``python -m continuum_gym.cli``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OCCLUSION = ["--env", "ContinuumGym/OcclusionAvoidance-v0", "--azimuth", "-60", "--elevation", "10",
             "--distance", "0.135", "--target", "-0.018", "0.004", "0.034"]
VIEW = ["--env", "ContinuumGym/ViewTracking-v0", "--azimuth", "-70", "--elevation", "25",
        "--distance", "0.44", "--target", "0.04", "0.07", "0.13"]
COMMON = ["--policy", "baseline", "--seed", "0", "--supersample", "2", "--gap", "4", "--no-plot", "--no-progress"]
#: output name -> ``continuum-gym render`` arguments (``--out`` is added)
COMMANDS = {
    "occlusion-avoidance.gif": [*OCCLUSION, *COMMON, "--size", "224", "--steps", "1000", "--every", "10"],
    "view-tracking.gif": [*VIEW, *COMMON, "--size", "192", "--steps", "400", "--every", "5"],
    "hero-occlusion-avoidance.png": [*OCCLUSION, *COMMON, "--size", "338", "--steps", "300"],
    "hero-view-tracking.png": [*VIEW, *COMMON, "--size", "224", "--steps", "400"],
}


def render(name: str, out: Path) -> Path:
    path = out / name
    command = [sys.executable, "-m", "continuum_gym.cli", "render", *COMMANDS[name], "--out", str(path)]
    print("continuum-gym render", " ".join(COMMANDS[name]), "--out", path, flush=True)
    subprocess.run(command, check=True, cwd=ROOT)
    return path


def stack(paths, out: Path, gap: int = 6) -> None:
    """The images one above the other, centred on white, ``gap`` white rows between them."""
    import imageio.v2 as imageio

    images = [np.asarray(imageio.imread(path))[..., :3] for path in paths]
    width = max(image.shape[1] for image in images)
    rows = []
    for image in images:
        row = np.full((image.shape[0], width, 3), 255, dtype=np.uint8)
        left = (width - image.shape[1]) // 2
        row[:, left:left + image.shape[1]] = image
        rows += [row, np.full((gap, width, 3), 255, dtype=np.uint8)]
    imageio.imwrite(out, np.concatenate(rows[:-1], axis=0))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].replace("``", ""))
    parser.add_argument("--out", default=str(ROOT / "docs" / "img"), help="output directory (default docs/img)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    render("occlusion-avoidance.gif", out)
    render("view-tracking.gif", out)
    with tempfile.TemporaryDirectory() as tmp:
        stills = [render(name, Path(tmp)) for name in ("hero-occlusion-avoidance.png", "hero-view-tracking.png")]
        stack(stills, out / "hero.png")
    for name in ("occlusion-avoidance.gif", "view-tracking.gif", "hero.png"):
        print(f"{out / name}: {(out / name).stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())

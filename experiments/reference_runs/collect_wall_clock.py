"""Write each reference run's wall-clock learning curve (``wall_clock.csv``) from its Ray Tune trial.

    python experiments/reference_runs/collect_wall_clock.py [--campaign ~/campaigns/reference] [--into reference-runs]

``continuum-gym train`` records the validation curve against env steps (``evaluations.npz``) but not
the time; the sweep's Tune trial does: one row of ``progress.csv`` per validation evaluation, with
``time_this_iter_s``, the wall-clock seconds since the trial's previous report (the first row: since
the trial process started, so it includes start-up). A trial that was killed and resumed from its
checkpoint starts ``time_total_s`` again from zero; its first report after the restart counts the
start-up and the steps redone since the checkpoint. So the elapsed wall-clock at each evaluation is
the running sum of ``time_this_iter_s`` over every report of the trial, restarts included; the part
of a killed session after its last report (lost work) is not in it.

Written per run, beside its ``evaluations.npz``: ``wall_clock.csv`` with ``timesteps``,
``elapsed_s`` (wall-clock since the trial started, s) and ``session`` (0, or how many restarts came
before that row). Every ``timesteps`` of ``evaluations.npz`` must have a row, else the run is reported
and left without the file. The times are those of a shared 2-core machine with other work running
(and, for the PPO rows, two trials at once): read them as an upper bound of what one free core needs.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FILE = "wall_clock.csv"


def trial_progress(campaign: Path, run_name: str, seed: int) -> Path | None:
    """The ``progress.csv`` of the Tune trial that trained ``run_name`` (seed ``seed``), or None."""
    group = campaign / run_name.rsplit("_seed", 1)[0] / "tune"
    matches = [p for p in sorted(group.glob("trainable_*/progress.csv"))
               if json.loads((p.parent / "params.json").read_text()).get("seed") == seed]
    if len(matches) > 1:
        raise ValueError(f"{run_name}: {len(matches)} Tune trials with seed {seed} in {group}")
    return matches[0] if matches else None


def wall_clock_rows(progress: Path) -> list[dict]:
    """[{timesteps, elapsed_s, session}] of one trial's reports, in order (see the module docstring)."""
    rows, elapsed, session = [], 0.0, 0
    with progress.open() as handle:
        for record in csv.DictReader(handle):
            if rows and int(record["iterations_since_restore"]) == 1:
                session += 1
            elapsed += float(record["time_this_iter_s"])
            rows.append({"timesteps": int(record["timesteps"]), "elapsed_s": round(elapsed, 3), "session": session})
    return rows


def collect(campaign: Path, into: Path) -> tuple[list[Path], dict]:
    """Write ``wall_clock.csv`` into every run of ``into`` that has a trial; returns (written, {run: problem})."""
    written, problems = [], {}
    for evaluations in sorted(into.glob("*/*/evaluations.npz")):
        run = evaluations.parent
        seed = int(run.name.rsplit("_seed", 1)[1])
        progress = trial_progress(campaign, run.name, seed)
        if progress is None:
            problems[run.name] = "no Tune trial found"
            continue
        rows = wall_clock_rows(progress)
        last = {row["timesteps"]: row for row in rows}  # a step evaluated twice (redone after a restart): the last
        steps = np.load(evaluations)["timesteps"]
        missing = [int(s) for s in steps if int(s) not in last]
        if missing:
            problems[run.name] = f"no Tune report at timesteps {missing}"
            continue
        with (run / FILE).open("w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=["timesteps", "elapsed_s", "session"], lineterminator="\n")
            writer.writeheader()
            writer.writerows(last[int(s)] for s in steps)
        written.append(run / FILE)
    return written, problems


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", default=str(Path.home() / "campaigns" / "reference"))
    parser.add_argument("--into", default=str(ROOT / "reference-runs"))
    args = parser.parse_args(argv)
    campaign = Path(args.campaign).expanduser()
    if not campaign.is_dir():
        print(f"collect_wall_clock: no campaign folder {campaign}", file=sys.stderr)
        return 2
    written, problems = collect(campaign, Path(args.into))
    for path in written:
        print(f"wrote {path}")
    for run, problem in problems.items():
        print(f"collect_wall_clock: {run}: {problem}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""collect_wall_clock.py's sum over a Ray Tune trial's reports, restarts included.

Not part of the package's suite (``make test`` runs ``tests/``; ``tests/evaluation/test_comparison.py`` checks the
``wall_clock.csv`` files the script wrote into ``reference-runs/``): ``pytest experiments/reference_runs``.
"""

from __future__ import annotations

from collect_wall_clock import wall_clock_rows


def test_wall_clock_sums_every_report_across_a_restart(tmp_path):
    progress = tmp_path / "progress.csv"
    progress.write_text("timesteps,time_this_iter_s,time_total_s,iterations_since_restore\n"
                        "100,10.0,10.0,1\n200,5.0,15.0,2\n"  # killed after 200; resumed from a checkpoint:
                        "300,20.0,20.0,1\n400,4.0,24.0,2\n")
    rows = wall_clock_rows(progress)
    assert [r["elapsed_s"] for r in rows] == [10.0, 15.0, 35.0, 39.0]
    assert [r["session"] for r in rows] == [0, 0, 1, 1]

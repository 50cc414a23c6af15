"""Kinematics and geometry speed: compiled kernels beside plain-numpy references in the same run.

    python benchmarks/kinematics.py [--json PATH] [--quick]

Each row reports calls (or robots) per second of the library and of the reference, and the ratio.
Before timing, each pair is checked to compute the same numbers. The JSON's ``units`` maps each key
(pattern) to its unit; ``source`` is the ``continuum_gym`` that was timed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import best_seconds, finish, machine, print_table  # noqa: E402
from numpy_reference_endoscope import endoscope_fk_jacobian_numpy  # noqa: E402
from numpy_reference_mbcr import fk_jacobian_numpy, potential_gradient_numpy, voi_numpy  # noqa: E402
from numpy_reference_overlap import overlap_ratio_numpy  # noqa: E402

import continuum_gym  # noqa: E402
from continuum_gym.geometry import (  # noqa: E402
    Frustum,
    overlap_ratio,
    overlap_ratio_reference,
    potential_gradient,
    visual_occlusion_index,  # noqa: E402
)
from continuum_gym.robots import (  # noqa: E402
    PAPER_PSPS,
    ContinuumEndoscope,
    DaVinciEndoscope,
    MultiBackboneRobot,
)

BATCH = 4096

#: Unit of every numeric result key (fnmatch patterns over the flattened, dot-joined keys), read by
#: benchmarks/compare.py. The numpy references run the same plain code in every revision, so they are
#: a control for the machine's speed; microseconds and ratio are restatements of the rates.
UNITS = {
    "*.per_second": "calls/s",
    "*.reference_per_second": "calls/s (control)",
    "*.microseconds": "us (derived)",
    "*.ratio": "x (derived)",
    "peak_rss_mib": "MiB",
    "machine.*": "info",
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="fewer repeats (for smoke tests)")
    args = parser.parse_args(argv)
    scale = 0.1 if args.quick else 1.0

    def n(calls):
        return max(1, int(calls * scale))

    rng = np.random.default_rng(0)
    robot = MultiBackboneRobot()
    lengths = np.array(robot.lengths)
    q = robot.psi_a.copy()
    qs = robot.psi_a + rng.normal(0, 0.3, (BATCH, 7)) * [1, 1, 1, 1, 1, 1, 0.01]
    endo = ContinuumEndoscope()
    q_endo = endo.case_study_start.copy()
    qs_endo = q_endo + rng.normal(0, 0.2, (BATCH, 6))
    davinci = DaVinciEndoscope()
    frustum = Frustum()
    p_a, R_a = davinci.forward_kinematics(davinci.case1)
    p_b, R_b = endo.forward_kinematics(q_endo)
    P_b, RR_b = endo.forward_kinematics(qs_endo)

    # Same numbers first.
    p, R, J = robot.forward_kinematics_and_jacobian(q)
    p_ref, R_ref, J_ref = fk_jacobian_numpy(q, lengths)
    assert np.allclose(J, J_ref, atol=1e-12) and np.allclose(p, p_ref, atol=1e-15)
    assert np.allclose(potential_gradient(robot, q, 0.0), potential_gradient_numpy(q, lengths, robot.stiffness,
                                                                                   PAPER_PSPS, 0.0), rtol=1e-9)
    assert abs(float(visual_occlusion_index(robot, q, 0.0)) - voi_numpy(q, lengths, 0.0)) < 1e-12
    assert np.allclose(endo.jacobian(q_endo), endoscope_fk_jacobian_numpy(q_endo, endo)[-1], atol=1e-12)
    assert abs(float(overlap_ratio(p_a, R_a, p_b, R_b)) - overlap_ratio_numpy(p_a, R_a, p_b, R_b, frustum)) < 1e-9

    rows = []
    results = {"machine": machine(), "unit": "calls per second (batched rows: robots or pairs per second)",
               "units": UNITS, "source": continuum_gym.__file__}

    def record(key, label, fast_seconds_per_item, ref_seconds_per_item, ref_label):
        fast = 1.0 / fast_seconds_per_item
        ref = 1.0 / ref_seconds_per_item
        results[key] = {"per_second": fast, "reference_per_second": ref, "ratio": fast / ref,
                        "microseconds": fast_seconds_per_item * 1e6, "reference": ref_label}
        rows.append((label, f"{fast_seconds_per_item * 1e6:9.2f} us", f"{fast:12,.0f}",
                     f"{ref_seconds_per_item * 1e6:9.1f} us", f"{fast / ref:8.1f}x", ref_label))

    numpy_fk = best_seconds(lambda: fk_jacobian_numpy(q, lengths), n(300))
    record("mbcr_fk_jacobian_single", "MBCR FK+Jacobian, single",
           best_seconds(lambda: robot.forward_kinematics_and_jacobian(q), n(20000)), numpy_fk, "numpy, single")
    record("mbcr_fk_jacobian_batch4096", "MBCR FK+Jacobian, batch 4096 (per robot)",
           best_seconds(lambda: robot.forward_kinematics_and_jacobian(qs), n(20)) / BATCH, numpy_fk, "numpy, single")
    record("mbcr_point_jacobians_force_gradient", "10 point Jacobians + force gradient",
           best_seconds(lambda: potential_gradient(robot, q, 0.0), n(10000)),
           best_seconds(lambda: potential_gradient_numpy(q, lengths, robot.stiffness, PAPER_PSPS, 0.0), n(100)),
           "numpy, single")
    record("voi_single", "VOI (126 samples), single",
           best_seconds(lambda: visual_occlusion_index(robot, q, 0.0), n(10000)),
           best_seconds(lambda: voi_numpy(q, lengths, 0.0), n(100)), "numpy, single")
    endo_ref = best_seconds(lambda: endoscope_fk_jacobian_numpy(q_endo, endo), n(300))
    record("endoscope_fk_jacobian_single", "endoscope FK+Jacobian, single",
           best_seconds(lambda: endo.fk_jacobian(q_endo), n(20000)), endo_ref, "numpy, single")
    record("endoscope_fk_jacobian_batch4096", "endoscope FK+Jacobian, batch 4096 (per robot)",
           best_seconds(lambda: endo.fk_jacobian(qs_endo), n(20)) / BATCH, endo_ref, "numpy, single")
    or_numpy = best_seconds(lambda: overlap_ratio_numpy(p_a, R_a, p_b, R_b, frustum), n(100))
    record("overlap_ratio_single", "exact OR, single",
           best_seconds(lambda: overlap_ratio(p_a, R_a, p_b, R_b), n(20000)), or_numpy, "numpy clipping, single")
    record("overlap_ratio_batch4096", "exact OR, batch 4096 (per pair)",
           best_seconds(lambda: overlap_ratio(p_a, R_a, P_b, RR_b), n(20)) / BATCH, or_numpy, "numpy clipping, single")
    record("overlap_ratio_vs_scipy", "exact OR vs scipy polytope reference",
           results["overlap_ratio_single"]["microseconds"] * 1e-6,
           best_seconds(lambda: overlap_ratio_reference(p_a, R_a, p_b, R_b), n(50)), "scipy HalfspaceIntersection")

    print_table(rows, ["operation", "time", "per second", "reference", "ratio", "reference is"])
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())

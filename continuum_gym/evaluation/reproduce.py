"""``continuum-gym reproduce``: every published result of both papers, with figures, a table and JSON.

Parts (paper-notes §3 gives the bands a faithful implementation lands in):
1. paper 000 task (a): hold psi_a's tip pose for 1500 iterations at 1 ms (projected gradient, gamma fixed),
   and the same from >= 50 seeded random starts with VOI ≈ 0.25;
2. paper 000 task (b): the 10 mm circle, minimum-norm vs projected gradient, gamma by eq (24);
3. paper 001 case studies 1 and 2: RMRC vs DR from Psi0;
4. paper 001 coverage map: OR > 0.8 over the yaw/pitch grid (41 x 41; 11 x 11 with --quick).
The reproduction runs the paper's models: no joint limits on the MBCR.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from continuum_gym.evaluation.io import write_json_atomic, write_text_atomic

#: The papers' printed values each row is compared with.
PAPER = {
    "hold": "0.25 -> 0.16 by ~800 it",
    "circle_mn": 0.29,
    "circle_pg": 0.11,
    "gamma": "-23.7 .. 25.1 deg",
    "coverage_dr": 61.07,
    "coverage_rmrc": 33.17,
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true",
                        help="reduced version for tests (11 x 11 grid, 10 sweep starts)")
    parser.add_argument("--json", help="write the results as nested JSON to this path")
    parser.add_argument("--out", default="results/reproduce", help="directory for figures and the Markdown table")
    parser.add_argument("--grid", type=int, default=None, help="coverage grid points per axis (default 41; 11 quick)")


def markdown_table(results: dict[str, Any]) -> str:
    from continuum_gym.baselines.scenarios import CASE_STUDIES

    h, s, c = results["hold"], results["hold_sweep"], results["circle"]
    cov = results["coverage"]
    rows = [
        ("(a) hold psi_a: VOI at 0 / 400 / 800 / 1500 it", PAPER["hold"],
         f"{h['voi'][0]:.3f} / {h['voi_at']['400']:.3f} / {h['voi_at']['800']:.3f} / {h['voi_at']['1500']:.3f}",
         "0.14-0.18 at 800 and 1500"),
        ("(a) hold psi_a: max tip drift", "-", f"{h['max_tip_drift_m'] * 1e3:.3f} mm", "<= 0.3 mm"),
        (f"(a) {s['n_starts']} random starts (VOI 0.25): final VOI median [p10, p90]", "-",
         f"{s['final_voi_median']:.3f} [{s['final_voi_p10']:.3f}, {s['final_voi_p90']:.3f}]; "
         f"decreased in {s['decreased_fraction'] * 100:.0f} %", "median 0.15 +- 0.1"),
        ("(b) circle, mean VOI, minimum norm", f"{PAPER['circle_mn']:.2f}", f"{c['minimum_norm']['mean_voi']:.3f}",
         "0.27-0.33"),
        ("(b) circle, mean VOI, projected gradient", f"{PAPER['circle_pg']:.2f}",
         f"{c['projected_gradient']['mean_voi']:.3f}", "0.14-0.20 and <= 0.7 x min-norm"),
        ("(b) gamma range", PAPER["gamma"], f"{c['gamma_min_deg']:.1f} .. {c['gamma_max_deg']:.1f} deg",
         "+-(16-19) deg"),
        ("(b) tip error mean / max, min-norm", "-",
         f"{c['minimum_norm']['mean_tip_error_m'] * 1e3:.3f} / {c['minimum_norm']['max_tip_error_m'] * 1e3:.3f} mm",
         "<= 0.04 mm"),
        ("(b) tip error mean / max, projected gradient", "-",
         f"{c['projected_gradient']['mean_tip_error_m'] * 1e3:.3f} / "
         f"{c['projected_gradient']['max_tip_error_m'] * 1e3:.3f} mm", "0.2-0.7 mm (the eps leak)"),
    ]
    for case in CASE_STUDIES:
        rr, dr = results[case]["resolved_rate"], results[case]["dimension_reduced"]
        rows.append((f"{case}: OR RMRC / DR", "plots only", f"{rr['or']:.3f} / {dr['or']:.3f}", "DR > RMRC"))
        rows.append((f"{case}: final position error RMRC / DR", "plots only",
                     f"{rr['position_error_m'] * 1e3:.2f} / {dr['position_error_m'] * 1e3:.4f} mm", "DR -> 0"))
        rows.append((f"{case}: final orientation error RMRC / DR", "plots only",
                     f"{rr['orientation_error_rad']:.3f} / {dr['orientation_error_rad']:.3f} rad", "-"))
    rows += [
        (f"coverage {cov['grid']}x{cov['grid']}: OR > 0.8, DR", f"{PAPER['coverage_dr']:.2f} %",
         f"{cov['dimension_reduced_percent']:.2f} %", "55-65 %"),
        (f"coverage {cov['grid']}x{cov['grid']}: OR > 0.8, RMRC", f"{PAPER['coverage_rmrc']:.2f} %",
         f"{cov['resolved_rate_percent']:.2f} %", "20-40 %"),
        ("coverage: DR vs RMRC", "+84.11 %",
         f"{(cov['dimension_reduced_percent'] / max(cov['resolved_rate_percent'], 1e-9) - 1) * 100:+.1f} %",
         "DR >= 1.5 x RMRC"),
    ]
    lines = ["| result | paper | this library | paper-notes §3 band |", "|---|---|---|---|"]
    lines += [f"| {a} | {b} | {c_} | {d} |" for a, b, c_, d in rows]
    lines.append("")
    lines.append("Wall time per part: " + ", ".join(f"{k} {v:.1f} s" for k, v in results["seconds"].items()))
    return "\n".join(lines)


def draw_figures(results: dict[str, Any], out: Path) -> list[Path]:
    import matplotlib

    from continuum_gym.baselines.scenarios import CASE_STUDIES, VIEW_DT

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    h, s, c = results["hold"], results["hold_sweep"], results["circle"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    axes[0].plot(h["voi"], color="tab:blue")
    axes[0].axhline(0.16, color="0.5", linestyle="--", label="paper: 0.16")
    axes[0].set(xlabel="iteration (1 ms)", ylabel="VOI", title="(a) hold psi_a: VOI (paper Fig. 5b)")
    axes[0].legend()
    axes[1].plot(h["elastic_energy"], color="tab:green")
    axes[1].set(xlabel="iteration (1 ms)", ylabel="elastic energy E (J)", title="(a) elastic energy (Fig. 5a)")
    axes[2].hist(s["final_voi"], bins=20, color="tab:purple")
    axes[2].axvline(s["final_voi_median"], color="k", linestyle="--", label=f"median {s['final_voi_median']:.3f}")
    axes[2].set(xlabel="final VOI after 1500 it", ylabel="starts", title=f"(a) {s['n_starts']} random starts, VOI 0.25")
    axes[2].legend()
    fig.tight_layout()
    paths.append(out / "hold.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    t = np.asarray(c["t"])
    for name, color in (("minimum_norm", "tab:red"), ("projected_gradient", "tab:blue")):
        axes[0].plot(t, c[name]["voi"], color=color, label=f"{name} (mean {c[name]['mean_voi']:.3f})")
    axes[0].set(xlabel="time (s)", ylabel="VOI", title="(b) circle: VOI (paper Fig. 3b: 0.29 vs 0.11)")
    axes[0].legend()
    axes[1].plot(t, c["projected_gradient"]["gamma_deg"], color="tab:orange")
    axes[1].set(xlabel="time (s)", ylabel="gamma (deg)", title="(b) endoscope rotation (paper: -23.7 .. 25.1 deg)")
    fig.tight_layout()
    paths.append(out / "circle.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    names = ["L0 (mm)", "phi", "theta1", "delta1", "theta2", "delta2"]
    for case in CASE_STUDIES:
        fig, axes = plt.subplots(2, 3, figsize=(15, 7))
        for row, name in enumerate(("resolved_rate", "dimension_reduced")):
            r = results[case][name]
            q = np.asarray(r["q_history"])
            steps = np.arange(len(q)) * 5 * VIEW_DT
            for k in range(6):
                axes[row, 0].plot(steps, q[:, k] * (1e3 if k == 0 else 1), label=names[k])
            axes[row, 0].set(xlabel="time (s)", title=f"{case} {name}: configuration")
            axes[row, 1].plot(steps, np.asarray(r["position_error_history_m"]) * 1e3, label="position (mm)")
            axes[row, 1].plot(steps, r["orientation_error_history_rad"], label="orientation (rad)")
            axes[row, 1].set(xlabel="time (s)", title="errors")
            axes[row, 2].plot(steps, r["or_history"], color="k")
            axes[row, 2].set(xlabel="time (s)", ylabel="OR", ylim=(0, 1.02), title=f"OR (final {r['or']:.3f})")
            axes[row, 0].legend(fontsize=7, ncol=2)
            axes[row, 1].legend(fontsize=7)
        fig.tight_layout()
        paths.append(out / f"{case}.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)

    cov = results["coverage"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    extent = np.degrees([-cov["yaw_pitch_limit_rad"], cov["yaw_pitch_limit_rad"]] * 2)
    for ax, name in zip(axes, ("resolved_rate", "dimension_reduced")):
        image = ax.imshow(np.asarray(cov[f"{name}_or"]).T, origin="lower", extent=extent, vmin=0, vmax=1,
                          cmap="viridis")
        ax.set(xlabel="yaw (deg)", ylabel="pitch (deg)",
               title=f"{name}\nOR > 0.8 on {cov[f'{name}_percent']:.1f} % of {cov['grid']}x{cov['grid']}")
    fig.colorbar(image, ax=axes, label="overlap ratio")
    paths.append(out / "coverage.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths


def run(args: argparse.Namespace) -> int:
    if args.grid is not None and args.grid < 2:
        print(f"continuum-gym reproduce: --grid must be an integer >= 2 (points per axis); got {args.grid}",
              file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from continuum_gym.evaluation.reproduction import reproduce

    results = reproduce(quick=args.quick, grid=args.grid)
    table = markdown_table(results)
    print(table)
    write_text_atomic(out / "reproduction.md", table + "\n")
    for path in draw_figures(results, out):
        print(f"wrote {path}")
    if args.json:
        write_json_atomic(args.json, results)
        print(f"wrote {args.json}")
    return 0

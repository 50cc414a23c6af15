"""Tables and the pre-declared keep / drop decision of the issue 38 campaign, from its validation results.

Reads ``<root>/results/val_{occ,view}.jsonl`` (written by ``val_eval.py``; validation split only) and
``<root>/results/train_cpu.jsonl`` (``run_queue.py``) and prints Markdown (also written to
``<root>/results/tables.md``): per config tag, each seed's final ``model.zip`` (checkpoints are listed apart)
and the mean over seeds. The newest record of a (tag, run, step) wins.

Decision rule, fixed before the campaign: a config is kept if the mean over its seeds beats the mean of the
shipped policies (tag ``shipped``) on validation: OcclusionAvoidance by hold headroom closed; ViewTracking by
the pan_tilt coverage proxy, with mean OR not worse by more than 0.01. Seeds 0, 1, 2 are the ones that ship.

    python scripts/optimum/summarize.py [--candidates occ_s2 vt_s3_lin6m]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path.home() / "campaigns" / "optimum"
COLUMNS = {"occ": [("mean_voi", "val mean VOI", 4), ("hold_voi", "hold VOI", 4), ("headroom", "headroom closed", 3),
                   ("tip_in_view_min", "min tip-in-view", 3)],
           "view": [("mean_or", "val mean OR", 3), ("coverage", "val pan_tilt coverage %", 2)]}


def read(path: Path) -> list[dict]:
    if not path.exists():
        return []
    latest: dict = {}
    for line in path.read_text().splitlines():
        if line.strip():
            record = json.loads(line)
            latest[(record["tag"], record["run"], record["step"])] = record
    return list(latest.values())


def cpu_seconds(root: Path) -> dict:
    out: dict = {}
    for record in read_lines(root / "results" / "train_cpu.jsonl"):
        key = (record["tag"], record["seed"])
        out[key] = out.get(key, 0.0) + record["cpu_s"]  # a resumed run adds its parts
    return out


def read_lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []


def by_tag(records: list[dict]) -> dict:
    out: dict = {}
    for record in records:
        if record["step"] is None:
            out.setdefault(record["tag"], []).append(record)
    return {tag: sorted(rows, key=lambda r: (r["seed"] is None, r["seed"])) for tag, rows in out.items()}


def table(short: str, records: list[dict], cpu: dict) -> list[str]:
    columns = COLUMNS[short]
    lines = [f"| tag | seeds | CPU-s | {' | '.join(c[1] for c in columns)} |", "|---" * (3 + len(columns)) + "|"]
    for tag, rows in by_tag(records).items():
        seeds = " / ".join(str(r["seed"]) if r["seed"] is not None else "-" for r in rows)
        cpus = " / ".join(f"{cpu[(tag, r['seed'])]:.0f}" for r in rows if (tag, r["seed"]) in cpu) or "-"
        cells = []
        for key, _, digits in columns:
            values = [r[key] for r in rows if key in r]
            each = " / ".join(f"{v:.{digits}f}" for v in values)
            cells.append(each + (f" (**{np.mean(values):.{digits}f}**)" if len(values) > 1 else ""))
        lines.append(f"| {tag} | {seeds} | {cpus} | {' | '.join(cells)} |")
    checkpoints = [r for r in records if r["step"] is not None]
    if checkpoints:
        lines += ["", "Checkpoints:", ""]
        for r in sorted(checkpoints, key=lambda r: (r["tag"], r["seed"], r["step"])):
            cells = ", ".join(f"{label} {r[key]:.{digits}f}" for key, label, digits in columns if key in r)
            lines.append(f"* {r['tag']} seed {r['seed']} step {r['step']}: {cells}")
    return lines


def decide(short: str, records: list[dict], tag: str) -> str:
    tags = by_tag(records)
    if tag not in tags or "shipped" not in tags:
        return f"{tag}: not decidable yet (needs both {tag} and shipped results)"
    mine, shipped = tags[tag], tags["shipped"]

    def mean(rows, key):
        return float(np.mean([r[key] for r in rows]))

    if short == "occ":
        a, b = mean(mine, "headroom"), mean(shipped, "headroom")
        kept = a > b
        why = f"hold headroom closed {a:.3f} vs shipped {b:.3f}"
    else:
        a, b = mean(mine, "coverage"), mean(shipped, "coverage")
        ora, orb = mean(mine, "mean_or"), mean(shipped, "mean_or")
        kept = a > b and ora >= orb - 0.01
        why = f"coverage {a:.2f} vs shipped {b:.2f} %, mean OR {ora:.3f} vs {orb:.3f}"
    return f"{tag} ({len(mine)} seeds): {'KEPT' if kept else 'not kept'}: {why}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT)
    parser.add_argument("--candidates", nargs="*", default=["occ_s2", "vt_s3_lin6m"])
    args = parser.parse_args(argv)
    cpu = cpu_seconds(args.root)
    out = []
    for short, title in (("occ", "OcclusionAvoidance-v0"), ("view", "ViewTracking-v0")):
        records = read(args.root / "results" / f"val_{short}.jsonl")
        out += [f"## {title} (validation split)", ""] + table(short, records, cpu) + [""]
        for tag in args.candidates:
            if tag.startswith({"occ": "occ", "view": "vt"}[short]):
                out.append(f"* decision: {decide(short, records, tag)}")
        out.append("")
    text = "\n".join(out)
    (args.root / "results" / "tables.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

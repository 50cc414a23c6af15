"""Timing helpers shared by the benchmark scripts: best-of-repeats rates, peak RSS, JSON output."""

from __future__ import annotations

import os
import platform
import resource
import sys
import time

from continuum_gym.evaluation.io import write_json_atomic as write_json  # noqa: F401  (re-export)


def best_seconds(fn, number: int, repeat: int = 5) -> float:
    """Best time per call over ``repeat`` runs of ``number`` calls (the machine is shared: take the minimum)."""
    fn()
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def peak_rss_mib() -> float:
    """Peak resident set size of this process (MiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def machine() -> dict:
    return {"python": sys.version.split()[0], "platform": platform.platform(), "cpus": os.cpu_count()}


def print_table(rows, headers) -> None:
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(headers)]
    print(" | ".join(str(h).ljust(w) for h, w in zip(headers, widths)))
    print("-|-".join("-" * w for w in widths))
    for row in rows:
        print(" | ".join(str(c).ljust(w) for c, w in zip(row, widths)))


def finish(results: dict, json_path) -> int:
    """Report peak RSS, write the JSON (atomically) if asked; the common tail of every benchmark."""
    results["peak_rss_mib"] = peak_rss_mib()
    print(f"peak RSS: {results['peak_rss_mib']:.0f} MiB")
    if json_path:
        write_json(json_path, results)
        print(f"wrote {json_path}")
    return 0

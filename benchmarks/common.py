"""Timing helpers shared by the benchmark scripts: best-of-repeats rates, peak RSS, JSON output."""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
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


def vector_env_rate(venv, actions, seconds: float, windows: int = 3) -> float:
    """Best robot-steps/s of ``venv.step`` over ``windows`` timed windows of ``seconds``, cycling through the
    action batches ``actions`` (B, N, k) after a reset and 3 warm-up steps (the machine is shared: the best)."""
    n = actions.shape[1]
    venv.reset(seed=0)
    for k in range(3):
        venv.step(actions[k % len(actions)])
    best = 0.0
    for _ in range(windows):
        count = 0
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            venv.step(actions[count % len(actions)])
            count += 1
        best = max(best, count * n / (time.perf_counter() - start))
    return best


def run_children_at_once(args: list[str], count: int, env: dict | None = None, what: str = "child") -> list[dict]:
    """Start ``count`` copies of the command ``args`` at once; the JSON each prints on its last line."""
    procs = [subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for _ in range(count)]
    results = []
    for proc in procs:
        out, err = proc.communicate()
        if proc.returncode != 0:
            raise RuntimeError(f"{what} failed:\n{err[-2000:]}")
        results.append(json.loads(out.strip().splitlines()[-1]))
    return results


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

"""Rendering speed: pybullet TinyRenderer frames per second of the scenes, and the cost of pixel_occlusion.

    python benchmarks/render.py [--json PATH] [--quick]

All in one process on one core (TinyRenderer is single-threaded). Each row cycles through hold-task
configurations with random gamma (``update`` + ``render`` per frame, as an environment would) and reports
the best of 5 repeats by wall clock and by this process's CPU time: on a shared machine the CPU-time rate
is what the code achieves on a free core. The target of the issue is the full scene's 128 x 128
endoscope image at >= 200 frames/s.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine, peak_rss_mib, print_table, write_json  # noqa: E402

from continuum_gym.baselines.scenarios import sample_hold_starts  # noqa: E402
from continuum_gym.render import OcclusionScene, ViewTrackingScene, pixel_occlusion  # noqa: E402
from continuum_gym.robots import MultiBackboneRobot  # noqa: E402


def best_seconds(fn, number: int, repeat: int = 5):
    """(wall, cpu): best seconds per call over ``repeat`` runs of ``number`` calls, by wall clock and CPU time."""
    fn()
    wall = cpu = float("inf")
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        for _ in range(number):
            fn()
        wall = min(wall, (time.perf_counter() - w) / number)
        cpu = min(cpu, (time.process_time() - c) / number)
    return wall, cpu


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="fewer frames (smoke test)")
    args = parser.parse_args(argv)
    frames = 20 if args.quick else 100

    rng = np.random.default_rng(0)
    robot = MultiBackboneRobot()
    Q = np.concatenate([sample_hold_starts(robot, 10, rng, voi_target=v, voi_tolerance=0.05)
                        for v in (0.05, 0.15, 0.25, 0.35, 0.45, 0.6)])
    G = rng.uniform(-np.pi, np.pi, len(Q))

    rss0 = _rss_mib()
    t0 = time.perf_counter()
    scene = OcclusionScene()
    build_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    extra = [OcclusionScene() for _ in range(4)]
    build_next = (time.perf_counter() - t0) / 4
    rss_per_scene = (_rss_mib() - rss0) / 5
    for s in extra:
        s.close()
    view = ViewTrackingScene()
    endo, dv = view.endoscope, view.davinci
    q_endo = endo.case_study_start + rng.normal(0.0, 0.15, (len(Q), 6)) * [0.05, 1, 1, 1, 1, 1]
    q_endo[:, 0] = np.clip(q_endo[:, 0], 0.0, 0.1)
    q_endo[:, 2] = np.clip(q_endo[:, 2], 0.0, np.pi / 4)
    q_endo[:, 4] = np.clip(q_endo[:, 4], 0.0, np.pi / 2)
    q_dv = dv.home + rng.uniform(-0.4, 0.4, (len(Q), 4)) * [0.02, 1, 1, 1]

    state = {"k": 0}

    def cycle(render):
        def step():
            k = state["k"] = (state["k"] + 1) % len(Q)
            render(k)
        return step

    rows, results = [], {"machine": machine(), "load_average": os.getloadavg(), "unit": "frames per second"}

    def record(key, label, seconds, note=""):
        wall, cpu = seconds
        results[key] = {"per_second": 1.0 / wall, "milliseconds": wall * 1e3, "per_cpu_second": 1.0 / cpu,
                        "cpu_milliseconds": cpu * 1e3, "note": note}
        rows.append((label, f"{1.0 / wall:9.1f}", f"{1.0 / cpu:9.1f}", f"{cpu * 1e3:7.2f} ms", note))

    def occ_frame(camera, size):
        def render(k):
            scene.update(Q[k], G[k])
            scene.render(camera, size, size)
        return render

    for size in (64, 128, 256):
        record(f"occlusion_endoscope_{size}", f"OcclusionScene endoscope {size}x{size} (update+render)",
               best_seconds(cycle(occ_frame("endoscope", size)), frames),
               "full scene; tissue image cached, robot rendered")
    full = OcclusionScene(cache_background=False)

    def full_frame(k):
        full.update(Q[k], G[k])
        full.render("endoscope", 128, 128)

    record("occlusion_endoscope_128_uncached", "  same, 128x128, cache_background=False",
           best_seconds(cycle(full_frame), frames), "robot, shaft and tissue rendered every frame")
    full.close()

    def both(k):
        scene.update(Q[k], G[k])
        scene.endoscope_frame(128, 128)

    record("occlusion_endoscope_frame_128", "OcclusionScene.endoscope_frame 128x128",
           best_seconds(cycle(both), frames), "image + pixel occlusion from one render")
    scene.update(Q[0], G[0])
    record("occlusion_endoscope_128_render_only", "OcclusionScene endoscope 128x128 (render only)",
           best_seconds(lambda: scene.render("endoscope", 128, 128), frames))
    record("occlusion_external_256", "OcclusionScene external 256x256 (update+render)",
           best_seconds(cycle(occ_frame("external", 256)), max(10, frames // 4)), "robot, shaft, cone, tissue")
    record("occlusion_update", "OcclusionScene.update alone",
           best_seconds(cycle(lambda k: scene.update(Q[k], G[k])), 10 * frames),
           f"{sum(len(v) for v in scene.body_ids.values())} bodies, all moved")

    def pixel_frame(size):
        def render(k):
            scene.update(Q[k], G[k])
            scene.pixel_occlusion(size)
        return render

    for size in (64, 128, 256):
        record(f"pixel_occlusion_scene_{size}", f"scene.update + scene.pixel_occlusion({size})",
               best_seconds(cycle(pixel_frame(size)), frames), "robot only, links outside the cone culled")
    pixel_occlusion(robot, Q[0], G[0])  # builds the cached scene
    record("pixel_occlusion_function_128", "pixel_occlusion(robot, q, gamma) at 128",
           best_seconds(cycle(lambda k: pixel_occlusion(robot, Q[k], G[k])), frames), "cached scene")

    def view_frame(camera, size):
        def render(k):
            view.update(q_endo[k], q_dv[k])
            view.render(camera, size, size)
        return render

    for camera in ("endoscope", "davinci"):
        record(f"view_tracking_{camera}_128", f"ViewTrackingScene {camera} 128x128 (update+render)",
               best_seconds(cycle(view_frame(camera, 128)), frames), "90 deg frustum camera, tissue plane")
    record("view_tracking_external_256", "ViewTrackingScene external 256x256 (update+render)",
           best_seconds(cycle(view_frame("external", 256)), max(10, frames // 4)))

    results["scene"] = {"build_first_s": build_first, "build_next_s": build_next, "rss_per_scene_mib": rss_per_scene,
                        "bodies": sum(len(v) for v in scene.body_ids.values())}
    results["peak_rss_mib"] = peak_rss_mib()
    print_table(rows, ("case", "frames/s (wall)", "frames/s (CPU)", "CPU per frame", "note"))
    print(f"\nOcclusionScene: first build {build_first:.2f} s (texture), next {build_next * 1e3:.0f} ms, "
          f"~{rss_per_scene:.1f} MiB RSS per scene; peak RSS {results['peak_rss_mib']:.0f} MiB; "
          f"load average {results['load_average'][0]:.2f} on {os.cpu_count()} CPUs")
    wall, cpu = results["occlusion_endoscope_128"]["per_second"], results["occlusion_endoscope_128"]["per_cpu_second"]
    print(f"target: 128x128 endoscope >= 200 frames/s: {wall:.0f} by wall clock, {cpu:.0f} per CPU second "
          f"({'met' if max(wall, cpu) >= 200 else 'NOT met'})")
    if args.json:
        write_json(args.json, results)
    scene.close()
    view.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

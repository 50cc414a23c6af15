"""Images at the cost of a state step: the batched renderer's frames per second beside pybullet's and the step's.

    python benchmarks/pixels.py [--json PATH] [--quick] [--num-envs 1024] [--threads 2] [--size 64]

For each environment, from the states of ``gym.make_vec(id, num_envs=N)`` after random steps:

- ``pixels``: building the scene from the rows' configurations (``camera.occlusion_scene`` /
  ``view_tracking_scene``: the kinematics) and rendering rgb + depth + segmentation at size x size into
  preallocated buffers, on ``--threads`` threads; ViewTracking renders both views (the continuum
  endoscope's and the da Vinci's), which count as one frame. Best of several timed windows, by wall clock
  and per CPU second of this process (what one core does; "cores used" is their ratio: on a shared machine
  the threads may get less than the cores asked for);
- ``pybullet``: the environment's pybullet scene (``core.make_scene()``) in the same run, one frame per row
  as ``show_row`` + ``render("endoscope")`` (+ ``render("davinci")``) of the same size; one
  ``getCameraImage`` gives its rgb, depth and segmentation. TinyRenderer is single-threaded;
- ``step``: the state step of the same vector env (N rows, ``--threads`` threads, random actions), in
  row-steps per second: what an image observation would be added to;
- ``memory``: bytes per row of the output buffers and of the scene arrays (exact), and the RSS the render
  call added per row.

The issue's goal: >= 20,000 frames/s at 64 x 64, N = 1024, 2 cores.

JSON keys: ``pixels.<env>.{frames_per_second,frames_per_cpu_second,build_us,render_us,cores_used}``,
``pybullet.<env>.frames_per_second``, ``ratio.<env>`` (pixels / pybullet, derived),
``step.<env>.steps_per_second``, ``memory.<env>.{buffers_bytes_per_row,scene_bytes_per_row,rss_bytes_per_row}``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table  # noqa: E402

import continuum_gym  # noqa: E402
from continuum_gym.camera import Renderer, allocate_frames, occlusion_scene, view_tracking_scene  # noqa: E402

OCCLUSION, VIEW = "ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0"
UNITS = {"pixels.*.frames_per_second": "frames/s", "pixels.*.frames_per_cpu_second": "frames/s",
         "pixels.*_us": "us", "pybullet.*": "frames/s", "ratio.*": "(derived)", "step.*": "steps/s",
         "memory.*": "info", "peak_rss_mib": "MiB", "machine.*": "info"}
GOAL = 20_000


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def best_rate(fn, count: int, seconds: float, windows: int = 5) -> tuple[float, float, float]:
    """(count per wall second, count per CPU second of this process, wall seconds per call), best windows."""
    fn()
    wall = cpu = per_call = 0.0
    for _ in range(windows):
        calls = 0
        w, c = time.perf_counter(), time.process_time()
        while time.perf_counter() - w < seconds:
            fn()
            calls += 1
        dw, dc = time.perf_counter() - w, time.process_time() - c
        wall, cpu = max(wall, calls * count / dw), max(cpu, calls * count / max(dc, 1e-9))
        per_call = dw / calls if per_call == 0.0 else min(per_call, dw / calls)
    return wall, cpu, per_call


def states(env_id: str, n: int, threads: int, seconds: float) -> tuple:
    """The vector env after random steps, and its state-step rate (row-steps per second)."""
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", num_threads=threads)
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.0, 1.0, (16, n) + venv.single_action_space.shape).astype(np.float32)
    k = iter(range(10**9))
    wall, _, _ = best_rate(lambda: venv.step(actions[next(k) % 16]), n, seconds, windows=3)
    return venv, venv.unwrapped.core, wall


def scene_bytes(scene) -> int:
    tubes = scene.tubes
    total = tubes.a.nbytes + tubes.b.nbytes + tubes.u.nbytes
    for view in scene.views.values():
        total += view.cameras.intrinsics.nbytes + view.cameras.poses.nbytes + view.cameras.k1.nbytes
    return total


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="short timings (smoke test)")
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", type=int, default=64)
    args = parser.parse_args(argv)
    seconds = 0.2 if args.quick else 1.0
    n, size = args.num_envs, args.size
    pybullet_frames = 30 if args.quick else 200
    results: dict = {"machine": machine(), "units": UNITS, "source": continuum_gym.__file__, "num_envs": n,
                     "threads": args.threads, "size": size, "load_average": os.getloadavg()}
    rows = []
    renderer = Renderer(threads=args.threads)
    for env_id in (OCCLUSION, VIEW):
        name = env_id.split("/")[1].split("-")[0]
        venv, core, step_rate = states(env_id, n, args.threads, seconds)
        views = ("endoscope",) if env_id == OCCLUSION else ("endoscope", "davinci")
        if env_id == OCCLUSION:
            q, gamma = core.q.copy(), core.gamma.copy()

            def build():
                return occlusion_scene(core.robot, core.cone, q, gamma, width=size)
        else:
            q, q_dv = core.q.copy(), np.array([core.davinci_configuration(row) for row in range(n)])

            def build():
                return view_tracking_scene(core.robot, core.davinci, core.frustum, q, q_dv, width=size)
        before = rss_bytes()
        buffers = {view: allocate_frames(n, size, size) for view in views}
        for view_buffers in buffers.values():
            for array in view_buffers.values():
                array.fill(0)  # touch the pages
        scene = build()

        def frame():
            built = build()
            for view in views:
                renderer.render(built, view, out=buffers[view])

        frame()
        rss_per_row = (rss_bytes() - before) / n
        wall, cpu, per_call = best_rate(frame, n, seconds)
        _, _, build_s = best_rate(build, n, seconds / 2, windows=3)
        render_s = per_call - build_s
        # pybullet, one row at a time
        pybullet_scene = core.make_scene()
        state = {"row": 0}

        def pybullet_frame():
            row = state["row"] = (state["row"] + 1) % n
            pybullet_scene.show_row(core, row)
            for view in views:
                pybullet_scene.render(camera=view, width=size, height=size)

        pybullet_wall, _, _ = best_rate(pybullet_frame, 1, pybullet_frames * 2e-3, windows=3)
        pybullet_scene.close()
        venv.close()
        buffers_per_row = sum(a.nbytes for b in buffers.values() for a in b.values()) / n
        results[f"pixels.{name}"] = {"frames_per_second": wall, "frames_per_cpu_second": cpu,
                                     "build_us": build_s / n * 1e6, "render_us": render_s / n * 1e6,
                                     "cores_used": wall / cpu if cpu else 0.0}
        results[f"pybullet.{name}.frames_per_second"] = pybullet_wall
        results[f"ratio.{name}"] = wall / pybullet_wall
        results[f"step.{name}.steps_per_second"] = step_rate
        results[f"memory.{name}"] = {"buffers_bytes_per_row": buffers_per_row,
                                     "scene_bytes_per_row": scene_bytes(scene) / n, "rss_bytes_per_row": rss_per_row}
        rows.append((name, f"{wall:,.0f}", f"{cpu:,.0f}", f"{wall / cpu:.2f}", f"{pybullet_wall:,.0f}",
                     f"{wall / pybullet_wall:,.0f}x", f"{step_rate:,.0f}",
                     f"{build_s / n * 1e6:.1f} + {render_s / n * 1e6:.1f} us",
                     f"{buffers_per_row / 1024:.0f} + {scene_bytes(scene) / n / 1024:.1f} KiB "
                     f"({rss_per_row / 1024:.0f})"))
    print(f"N = {n}, {size} x {size}, rgb + depth + segmentation, {args.threads} threads; load average "
          f"{results['load_average'][0]:.2f} on {os.cpu_count()} CPUs")
    print_table(rows, ["env", "frames/s (wall)", "frames/CPU s", "cores used", "pybullet frames/s", "ratio",
                       "state steps/s", "build + render per frame (wall)", "memory per row: buffers + scene (RSS)"])
    for name in ("OcclusionAvoidance", "ViewTracking"):
        rate = results[f"pixels.{name}"]["frames_per_second"]
        print(f"goal >= {GOAL:,} frames/s, {name}: {rate:,.0f} by wall clock "
              f"({'met' if rate >= GOAL else 'NOT met'}), {results[f'pixels.{name}']['frames_per_cpu_second']:,.0f} "
              f"per CPU second")
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())

"""``continuum-gym precompile``: compile the kernels once per install, so that a first ``step()`` takes a second.

It runs every registered environment (each built-in task with each analytic base controller and without
one, a single env and a native vector env) and the overlap ratio's entry points in a child process whose
compiled kernels go to the precompiled set (:mod:`continuum_gym.robots.compiled`). The set is built in a
new directory and moved into place when complete, so a killed run leaves the previous set (or none),
never half of one. ``make setup`` runs it; so should an image or wheel build (``--portable`` for code
that runs on any x86-64 CPU).

``continuum-gym precompile --import MODULE --env ID`` compiles what ``gym.make(ID)`` of a user's id builds and
steps (its robot, its own controller and reward terms, its model error if the id sets one; and its native vector
env) in this process, into numba's cache where run-time compiles go: the first ``gym.make(ID)`` afterwards
compiles nothing. The packaged set is left as it is (it holds the package's environments only).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

# The name robots.compiled reads the manifest by (it is not imported here: `precompile --help` stays light).
MANIFEST = "manifest.json"

_WORKER_FLAG = "--worker"
#: Starts a worker's progress lines on its stdout; its other stdout lines are passed on as they are.
_PROGRESS = "continuum-gym-precompile-progress"
#: No rate and no remaining time: the steps differ in cost by orders of magnitude (an env's first step
#: compiles most of its kernels, the next ones reuse them), so any extrapolation from them would be wrong.
_BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} steps [{elapsed}{postfix}]"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None, help="directory of the precompiled set (default: "
                        "CONTINUUM_GYM_PRECOMPILED_DIR or continuum_gym/_precompiled)")
    parser.add_argument("--portable", action="store_true",
                        help="compile for LLVM's 'generic' CPU: loads on any machine of this architecture (measured "
                        "as fast as code compiled for this CPU, same bits: see the README)")
    parser.add_argument("--check", action="store_true",
                        help="only report whether the set matches these sources (exit status 1 if not)")
    parser.add_argument("--env", nargs="+", default=None, metavar="ID",
                        help="compile what gym.make(ID) builds and steps for these ids instead, e.g. your variant's "
                        "(with --import MODULE), into numba's cache: its first gym.make then compiles nothing")
    parser.add_argument(_WORKER_FLAG, default=None, choices=_env_ids(), help=argparse.SUPPRESS)


def read_manifest(directory: Path) -> dict | None:
    """The set's manifest (digest, CPU, numba version, kernels, seconds), or None when there is no set."""
    try:
        return json.loads((directory / MANIFEST).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def status(directory: Path) -> tuple[bool, str]:
    """Whether the set in ``directory`` was built from these sources, and a sentence saying so."""
    from continuum_gym.robots.compiled import source_digest

    manifest = read_manifest(directory)
    if manifest is None:
        return False, (f"no precompiled set in {directory}: kernels compile on first use "
                       "(run `continuum-gym precompile`)")
    if manifest.get("digest") != source_digest():
        return False, (f"the precompiled set in {directory} was built from other sources or another compiler stack: "
                       "it is ignored (rerun `continuum-gym precompile`)")
    return True, (f"precompiled set in {directory}: {manifest['kernels']} compiled kernels for CPU "
                  f"'{manifest['cpu']}', built in {manifest['seconds']:.0f} s")


def warm_up(env_id: str, report: Callable[[str], None] = lambda message: None) -> None:
    """Build and step every configuration of ``env_id`` whose kernels a user, the main job or the tests compile.

    ``report`` hears ``total <n>`` first, then ``done`` after each of the n steps; a worker prints them
    (after :data:`_PROGRESS`) for the parent, whose one progress bar counts the steps of every worker.
    """
    import gymnasium as gym

    import continuum_gym  # noqa: F401  (registers the ids)
    from continuum_gym.envs.spec import get_spec

    spec = get_spec(env_id)
    config = spec.config_class
    test_only, builtin = config.test_only_tasks, config.builtin_tasks
    work = [{"task": task, "task_split": "test" if task in test_only else "train", "base_controller": base}
            for base in (*spec.baselines, None) for task in builtin]
    # the step with a model-error plant (its own specialisation of the step kernel) and the batched renderer of the
    # image observations (camera/), as evaluate --model-error, the pixel policies and their tests run them
    work += [{"model_error": "severe"}, {"obs_mode": "rgb+depth+segmentation"}]
    # the bases the package ships as plug-ins (ViewTracking's distilled_optimum), which evaluate gives a row
    work += [{"base_controller": reference.rpartition(":")[2]} for reference in config.packaged_controllers]
    from continuum_gym.envs.helpers import HelperWrapper, helper_names

    helpers = helper_names(env_id)
    report(f"total {len(work) + len(helpers) + 3}")  # the single envs, the helpers, two vector envs, the library
    for kwargs in work:
        _step_twice(gym.make(env_id, **kwargs))
        report("done")
    for name in helpers:  # a helper's own kernels (ViewTracking's overlap lookahead), on the joint residual
        _step_twice(HelperWrapper(gym.make(env_id, residual_space="joint"), [name]))
        report("done")
    for num_threads in (1, 2):
        _step_twice(gym.make_vec(env_id, num_envs=64, vectorization_mode="vector_entry_point", num_threads=num_threads))
        report("done")
    from continuum_gym.evaluation.reproduction import warm_ups

    for part in warm_ups(spec.env_id):  # the env's library API, as ``continuum-gym reproduce`` calls it
        part()
    report("done")


def warm_up_id(env_id: str) -> None:
    """Build and step what ``gym.make(env_id)`` builds, with the keywords the id was registered with, and its native
    vector env (one and two threads) when the id has one: every kernel they run is compiled (or loaded) now."""
    import gymnasium as gym

    _step_twice(gym.make(env_id))
    if gym.spec(env_id).vector_entry_point is not None:
        for num_threads in (1, 2):
            _step_twice(gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point",
                                     num_threads=num_threads))


def compile_ids(env_ids: list) -> int:
    """``precompile --env``: :func:`warm_up_id` of each id, saying what it did; the exit status."""
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.robots.compiled import ANNOUNCER

    try:
        for env_id in env_ids:
            get_spec(env_id)
    except ValueError as error:
        print(f"continuum-gym precompile: {error}", file=sys.stderr)
        return 2
    before = 0  # the first id's count includes what importing its plug-ins compiled (e.g. its controller)
    for env_id in env_ids:
        print(f"continuum-gym precompile: compiling what gym.make({env_id!r}) runs (a minute or a few, once)",
              file=sys.stderr, flush=True)
        start = time.perf_counter()
        warm_up_id(env_id)
        compiled, before = ANNOUNCER.count - before, ANNOUNCER.count
        done = (f"{compiled} kernel(s) compiled, now in numba's cache ({time.perf_counter() - start:.0f} s)"
                if compiled else "nothing to compile, every kernel was cached already")
        print(f"continuum-gym precompile: {env_id}: {done}; its first gym.make compiles nothing", flush=True)
    return 0


def _step_twice(env) -> None:
    """Reset and two seeded random steps: every kernel of a reset and a step compiles."""
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(2):
        env.step(env.action_space.sample())
    env.close()


def _env_ids() -> list:
    from continuum_gym.envs.spec import ENV_SPECS

    return list(ENV_SPECS)


def build(out: Path, portable: bool = False, env_ids: list | None = None) -> dict:
    """Compile into a fresh directory beside ``out`` and move it into place; return the manifest.

    One worker process per environment, run at once (each writes its own layer of the set), so the
    build takes about as long as the slowest environment's first compile. One progress bar (on a
    terminal) counts the steps of every worker; a line says when each environment is done.
    """
    from continuum_gym.robots.compiled import PORTABLE_CPU, digest_of, source_hashes

    out = out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    building = out.with_name(f"{out.name}.building-{os.getpid()}")
    shutil.rmtree(building, ignore_errors=True)
    # The workers' progress is the bar: their per-kernel compile lines would only interleave with it.
    environ = dict(os.environ, CONTINUUM_GYM_PRECOMPILED_DIR=str(building), CONTINUUM_GYM_COMPILE_MESSAGES="0")
    if portable:
        environ["NUMBA_CPU_NAME"] = PORTABLE_CPU
    start = time.perf_counter()
    try:
        codes = _run_workers({env_id: [sys.executable, "-m", "continuum_gym.precompile", _WORKER_FLAG, env_id]
                              for env_id in env_ids or _env_ids()}, environ, start)
        if any(codes):
            raise RuntimeError(f"continuum-gym precompile: a worker failed (exit codes {codes}); the previous set, "
                               "if any, is left as it was")
        import numba

        sources = source_hashes()
        manifest = {
            "digest": digest_of(sources),
            "cpu": PORTABLE_CPU if portable else _host_cpu(),
            "numba": numba.__version__,
            "kernels": sum(1 for _ in building.rglob("*.nbc")),
            "seconds": round(time.perf_counter() - start, 1),
            "sources": sources,  # lets a process skip parsing the files it finds unchanged (source_digest)
        }
        (building / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
        previous = out.with_name(f"{out.name}.previous-{os.getpid()}")
        if out.exists():
            out.rename(previous)
        building.rename(out)
        shutil.rmtree(previous, ignore_errors=True)
    finally:
        shutil.rmtree(building, ignore_errors=True)
    return manifest


def _run_workers(commands: dict, environ: dict, start: float) -> list:
    """Run the workers ({env id: command}) at once, their progress as one bar; return their exit codes."""
    import queue
    import threading

    from tqdm.auto import tqdm

    lines: queue.Queue = queue.Queue()

    def relay(env_id, stream):  # a thread per worker: its pipe, if nobody read it, would fill and block it
        for line in stream:
            lines.put((env_id, line.rstrip("\n")))
        stream.close()
        lines.put((env_id, None))

    workers = {env_id: subprocess.Popen(command, env=environ, stdout=subprocess.PIPE, text=True)
               for env_id, command in commands.items()}
    for env_id, worker in workers.items():
        threading.Thread(target=relay, args=(env_id, worker.stdout), daemon=True).start()
    print(f"continuum-gym precompile: compiling the kernels of {len(workers)} environment(s) in parallel "
          "(a few minutes, once)", file=sys.stderr, flush=True)
    # A bar redrawn in place reads well on a terminal only; in a log the line per environment says enough.
    bar = tqdm(total=None, desc="precompile", bar_format=_BAR_FORMAT, disable=not sys.stderr.isatty())
    running = list(workers)
    totals: dict = {}  # steps each worker announced; the bar's total is known only once every worker spoke

    def announce(env_id, steps):
        totals.setdefault(env_id, steps)
        if len(totals) == len(workers):
            bar.total = sum(totals.values())
        bar.refresh()

    def names(env_ids):
        return ", ".join(env_id.split("/")[-1] for env_id in env_ids)

    bar.set_postfix_str(f"running {names(running)}")
    while running:
        env_id, line = lines.get()
        if line is None:  # the worker closed its stdout: it has finished
            running.remove(env_id)
            announce(env_id, 0)  # a worker that died before announcing its steps has none left
            bar.set_postfix_str(f"running {names(running)}" if running else "")
            if workers[env_id].wait() == 0:
                tqdm.write(f"continuum-gym precompile: {names([env_id])} done after "
                           f"{time.perf_counter() - start:.0f} s", file=sys.stderr)
        elif not line.startswith(_PROGRESS):
            tqdm.write(line)
        elif line.split()[1] == "total":
            announce(env_id, int(line.split()[2]))
        else:
            bar.update()
    bar.close()
    return [worker.wait() for worker in workers.values()]


def _host_cpu() -> str:
    import llvmlite.binding as llvm

    return llvm.get_host_cpu_name()


def run(args: argparse.Namespace) -> int:
    if args.worker:
        from continuum_gym.robots.compiled import writing_precompiled

        with writing_precompiled(layer=args.worker.split("/")[-1]):
            warm_up(args.worker, lambda message: print(_PROGRESS, message, flush=True))
        return 0
    if args.env:
        given = [flag for flag, value in (("--check", args.check), ("--out", args.out), ("--portable", args.portable))
                 if value]
        if given:
            print(f"continuum-gym precompile: {' and '.join(given)} concern the packaged set; --env compiles into "
                  "numba's cache (where run-time compiles go): leave one or the other out", file=sys.stderr)
            return 2
        return compile_ids(args.env)
    from continuum_gym.robots.compiled import precompiled_dir

    out = Path(args.out) if args.out else precompiled_dir()
    if args.check:
        ok, message = status(out)
        print(message)
        return 0 if ok else 1
    manifest = build(out, portable=args.portable)
    print(f"continuum-gym precompile: {manifest['kernels']} kernels for CPU '{manifest['cpu']}' in "
          f"{manifest['seconds']:.0f} s -> {out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m continuum_gym.precompile``: the command's worker processes (``continuum-gym precompile`` for users)."""
    parser = argparse.ArgumentParser(prog="continuum-gym precompile")
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())

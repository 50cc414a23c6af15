"""The precompiled kernel set: what it serves, when it refuses to, and that every package kernel uses it."""

from __future__ import annotations

import importlib
import io
import json
import os
import pkgutil
import re
import subprocess
import sys
import textwrap
import time

import pytest
from numba.core.registry import CPUDispatcher

import continuum_gym
from continuum_gym import precompile
from continuum_gym.robots import compiled

# A kernel in its own module file (numba caches only functions with a source file). Each child process
# calls it and reports its result's bits and whether numba found it in a cache or compiled it.
TOY_MODULE = '''
import math

from continuum_gym.robots.compiled import kernel


@kernel(inline="always")
def helper(x):
    return math.sin(x) * math.exp(-0.5 * x)


@kernel
def toy(n):
    total = 0.0
    for i in range(n):
        total += helper(0.001 * i)
    return total
'''

CHILD = '''
import json, sys
sys.path.insert(0, sys.argv[1])
from continuum_gym.robots import compiled
if sys.argv[2] == "stale":
    compiled.source_digest = lambda: "another source tree"
import toy_kernels
if sys.argv[2] == "write":
    with compiled.writing_precompiled(layer="toy"):
        value = toy_kernels.toy(1000)
else:
    value = toy_kernels.toy(1000)
stats = toy_kernels.toy.stats
print(json.dumps({"bits": value.hex(), "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
'''


def run_child(tmp_path, mode: str, **env) -> dict:
    environ = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"),
                   CONTINUUM_GYM_PRECOMPILED_DIR=str(tmp_path / "set"), **env)
    out = subprocess.run([sys.executable, "-c", CHILD, str(tmp_path / "src"), mode], env=environ,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def nbc_files(directory) -> list:
    return sorted(path.name for path in directory.rglob("*.nbc")) if directory.exists() else []


@pytest.fixture
def toy_tree(tmp_path):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "toy_kernels.py").write_text(TOY_MODULE)
    return tmp_path


def test_precompiled_set_serves_the_same_code_without_numba_cache(toy_tree):
    written = run_child(toy_tree, "write")
    assert written["misses"] == 1 and written["hits"] == 0  # compiled, into the set only
    assert nbc_files(toy_tree / "set" / "toy") and not nbc_files(toy_tree / "numba-cache")

    loaded = run_child(toy_tree, "read")
    assert loaded == {"bits": written["bits"], "hits": 1, "misses": 0}
    assert not nbc_files(toy_tree / "numba-cache")  # nothing compiled, so nothing saved

    # With the set switched off the same kernel compiles and goes to numba's own cache, same bits.
    jit = run_child(toy_tree, "read", CONTINUUM_GYM_PRECOMPILED="0")
    assert jit == {"bits": written["bits"], "hits": 0, "misses": 1}
    assert nbc_files(toy_tree / "numba-cache")


def test_the_set_still_serves_a_kernel_whose_file_gained_lines_and_docstrings(toy_tree):
    written = run_child(toy_tree, "write")
    moved = '"""Toy kernels, documented."""\n# the kernels moved down by a few lines\n\n' + TOY_MODULE
    (toy_tree / "src" / "toy_kernels.py").write_text(moved.replace("def toy(n):", 'def toy(n):\n    """A sum."""'))
    assert run_child(toy_tree, "read") == {"bits": written["bits"], "hits": 1, "misses": 0}


def test_a_compile_names_its_kernel_once_and_a_cache_hit_says_nothing(toy_tree):
    """A compile that takes seconds to minutes says which kernel compiles and that it is cached afterwards:
    one line for the kernel called (not for the helpers it compiles), none when it comes from a cache."""
    environ = {k: v for k, v in os.environ.items() if k != "CONTINUUM_GYM_COMPILE_MESSAGES"}
    environ.update(NUMBA_CACHE_DIR=str(toy_tree / "numba-cache"), CONTINUUM_GYM_PRECOMPILED_DIR=str(toy_tree / "set"))

    def child(**env):
        out = subprocess.run([sys.executable, "-c", CHILD, str(toy_tree / "src"), "read"], env={**environ, **env},
                             capture_output=True, text=True, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1]), [line for line in out.stderr.splitlines()
                                                                 if "compiling" in line]

    stats, said = child()
    assert stats["misses"] == 1 and len(said) == 1, said
    assert said[0].startswith("continuum-gym: compiling toy_kernels.toy ") and "cached on disk afterwards" in said[0]
    stats, said = child()
    assert stats["hits"] == 1 and said == []  # from numba's cache: nothing compiles, nothing is said
    for entry in (toy_tree / "numba-cache").rglob("*.nb*"):
        entry.unlink()
    stats, said = child(CONTINUUM_GYM_COMPILE_MESSAGES="0")
    assert stats["misses"] == 1 and said == []  # compiled again, silenced


def test_a_users_uncached_kernel_is_named_with_the_advice_to_cache_it(capsys, monkeypatch):
    import numba

    monkeypatch.delenv("CONTINUUM_GYM_COMPILE_MESSAGES", raising=False)

    @numba.njit
    def users_kernel(x):
        return 2.0 * x

    before = compiled.ANNOUNCER.count
    assert users_kernel(1.5) == 3.0
    said = [line for line in capsys.readouterr().err.splitlines() if "compiling" in line]
    assert len(said) == 1 and ".users_kernel with numba" in said[0] and "@njit(cache=True)" in said[0]
    assert compiled.ANNOUNCER.count == before + 1
    users_kernel(2.5)  # compiled already: nothing more
    assert "compiling" not in capsys.readouterr().err and compiled.ANNOUNCER.count == before + 1


def test_set_built_from_other_sources_is_ignored(toy_tree):
    run_child(toy_tree, "write")
    stale = run_child(toy_tree, "stale")
    assert stale["hits"] == 0 and stale["misses"] == 1


def test_digest_follows_the_code_of_every_source_file_not_its_docstrings_or_comments(tmp_path, monkeypatch):
    tree = tmp_path / "pkg"
    (tree / "robots").mkdir(parents=True)
    (tree / "robots" / "a.py").write_text('"""Module a."""\nx = 1\n\n\ndef f(y):\n    """Twice."""\n    return 2 * y\n')
    (tree / "b.py").write_text("y = 2\n")
    monkeypatch.setattr(compiled, "PACKAGE_ROOT", tree)
    monkeypatch.setenv("CONTINUUM_GYM_PRECOMPILED_DIR", str(tmp_path / "no-set"))

    def digest_after(path, text):
        (tree / path).write_text(text)
        compiled.source_digest.cache_clear()
        return compiled.source_digest()

    try:
        first = digest_after("b.py", "y = 2\n")
        kept = [digest_after("robots/a.py", '"""Module a, edited."""\n# a comment\nx = 1  # one\n\n\n'
                                            'def f(y):\n    """Twice, edited."""\n    return 2 * y  # the same\n'),
                digest_after("b.py", "\n\ny = 2\n")]  # code moved down by two lines
        changed = [digest_after("b.py", "y = 3\n"), digest_after("robots/a.py", "x = 1\n")]
    finally:
        compiled.source_digest.cache_clear()
    assert kept == [first, first]
    assert len({first, *changed}) == 3


def test_a_manifests_hashes_are_reused_only_for_unchanged_bytes(tmp_path, monkeypatch):
    assert precompile.MANIFEST == compiled.MANIFEST  # the file precompile writes is the one the kernels read
    (tmp_path / "a.py").write_text("x = 1\n")
    monkeypatch.setattr(compiled, "PACKAGE_ROOT", tmp_path)
    hashes = compiled.source_hashes()
    assert hashes["a.py"][1] == compiled.code_hash(b"x = 1  # comment\n") != compiled.code_hash(b"x = 2\n")
    raw = hashes["a.py"][0]
    assert compiled.source_hashes({"a.py": [raw, "from the manifest"]})["a.py"] == [raw, "from the manifest"]
    assert compiled.source_hashes({"a.py": ["other bytes", "from the manifest"]}) == hashes


def test_switch_names_the_variable_and_its_values(monkeypatch):
    monkeypatch.setenv("CONTINUUM_GYM_PRECOMPILED", "maybe")
    with pytest.raises(ValueError, match="CONTINUUM_GYM_PRECOMPILED must be 0 or 1"):
        compiled.precompiled_enabled()
    monkeypatch.setenv("CONTINUUM_GYM_PRECOMPILED", "0")
    assert not compiled.precompiled_enabled()


def test_every_package_kernel_looks_in_the_precompiled_set():
    kernels = []
    for info in pkgutil.walk_packages(continuum_gym.__path__, "continuum_gym."):
        module = importlib.import_module(info.name)
        kernels += [value for value in vars(module).values()
                    if isinstance(value, CPUDispatcher) and value.py_func.__module__ == info.name]
    assert len(kernels) > 100
    plain = [k.py_func.__qualname__ for k in kernels if not isinstance(k._cache, compiled.PrecompiledFirstCache)]
    assert plain == []


def test_status_reports_missing_stale_and_fresh_sets(tmp_path):
    ok, message = precompile.status(tmp_path)
    assert not ok and "no precompiled set" in message
    manifest = {"digest": "other", "cpu": "generic", "numba": "0", "kernels": 3, "seconds": 1.0}
    (tmp_path / precompile.MANIFEST).write_text(json.dumps(manifest))
    ok, message = precompile.status(tmp_path)
    assert not ok and "other sources" in message
    manifest["digest"] = compiled.source_digest()
    (tmp_path / precompile.MANIFEST).write_text(json.dumps(manifest))
    ok, message = precompile.status(tmp_path)
    assert ok and "3 compiled kernels" in message


def test_check_flag_exit_status(tmp_path):
    command = [sys.executable, "-m", "continuum_gym.cli", "precompile", "--check", "--out", str(tmp_path)]
    assert subprocess.run(command, capture_output=True).returncode == 1
    (tmp_path / precompile.MANIFEST).write_text(json.dumps(
        {"digest": compiled.source_digest(), "cpu": "x", "numba": "0", "kernels": 1, "seconds": 1.0}))
    out = subprocess.run(command, capture_output=True, text=True)
    assert out.returncode == 0, textwrap.shorten(out.stderr, 300)


def test_a_failed_build_leaves_the_previous_set_as_it_was(tmp_path):
    out = tmp_path / "set"
    (out / "layer").mkdir(parents=True)
    (out / "layer" / "kernel.nbc").write_bytes(b"previous")
    (out / precompile.MANIFEST).write_text("{}")
    with pytest.raises(RuntimeError, match="a worker failed"):
        precompile.build(out, env_ids=["ContinuumGym/NoSuchEnv-v0"])  # the worker refuses the id
    assert (out / "layer" / "kernel.nbc").read_bytes() == b"previous"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["set"]  # no half-built directory left


# A stand-in for a precompile worker: its progress lines, a line of its own, its exit status.
FAKE_WORKER = '''
import sys
marker, status = sys.argv[1], int(sys.argv[2])
print(marker, "total 2", flush=True)
print("a line of the worker's own", flush=True)
print(marker, "done", flush=True)
if status == 0:
    print(marker, "done", flush=True)
sys.exit(status)
'''


@pytest.mark.parametrize("terminal", [False, True])
def test_the_workers_progress_is_one_bar_without_an_estimate(terminal, capsys, monkeypatch):
    """Parallel workers feed one bar (a terminal only), with no rate or remaining time; a line per finished env."""
    class Stderr(io.StringIO):
        def isatty(self):
            return terminal

    stderr = Stderr()
    monkeypatch.setattr(sys, "stderr", stderr)
    commands = {f"ContinuumGym/Toy{k}-v0": [sys.executable, "-c", FAKE_WORKER, precompile._PROGRESS, str(status)]
                for k, status in enumerate((0, 0, 3))}
    codes = precompile._run_workers(commands, dict(os.environ), time.perf_counter())
    assert codes == [0, 0, 3]
    err, out = stderr.getvalue(), capsys.readouterr().out
    assert out.count("a line of the worker's own") == 3 and precompile._PROGRESS not in out + err
    for name, lines in (("Toy0-v0", 1), ("Toy1-v0", 1), ("Toy2-v0", 0)):  # the failed worker is not "done"
        assert err.count(f"continuum-gym precompile: {name} done after") == lines
    assert "\x1b[A" not in err  # no bar drawn above another: there is only one
    assert not re.search(r"it/s|s/it|<\d", err)  # neither a rate nor a remaining time
    if terminal:
        assert "precompile: 100%" not in err and "5/6 steps" in err  # the steps of every worker, in one bar
    else:
        assert "steps" not in err  # a bar redrawn in place would garble a log


VARIANT_MODULE = '''
"""A user's variant: a 2-segment robot and its own controller, registered at import."""
import numpy as np
from gymnasium.envs.registration import register, registry
from numba import njit

from continuum_gym.registry import register_controller, register_robot
from continuum_gym.robots import MultiBackboneRobot
from continuum_gym.robots.mbcr_kernels import make_workspace, tip_kernel

ENV_ID = "MyTest/PrecompiledTwoSeg-v0"
BASE = "ContinuumGym/OcclusionAvoidance-v0"


@njit(cache=True)
def mytest_tracker(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
    ws = make_workspace(robot.lengths.shape[0])
    p, R, J = np.empty(3), np.empty((3, 3)), np.empty((6, q.shape[0]))
    tip_kernel(q, robot, ws, p, R, J)
    out[: q.shape[0]] = params[0] * (J[:3].T @ (p_des - p))
    out[q.shape[0]] = 0.0


register_robot("mytest-2seg", MultiBackboneRobot(lengths=(0.030, 0.025)), replace=True)
register_controller("mytest_tracker", mytest_tracker, env=BASE, params=[20.0], replace=True)
if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceEnv",
             vector_entry_point="continuum_gym.envs.occlusion:OcclusionAvoidanceVectorEnv",
             kwargs={"robot": "mytest-2seg", "base_controller": "mytest_tracker"})
'''

FIRST_MAKE = '''
import numpy as np, gymnasium as gym
import mytest_variant
env = gym.make(mytest_variant.ENV_ID)
env.reset(seed=0)
env.step(np.zeros(env.action_space.shape, dtype=np.float32))
print(env.action_space.shape)
'''


def test_precompile_env_compiles_what_a_variants_first_make_runs(tmp_path):
    """`continuum-gym precompile --import MODULE --env ID` compiles the variant's kernels (its own controller, its
    robot's step): the first gym.make(ID) of a new process afterwards compiles nothing and says nothing."""
    (tmp_path / "mytest_variant.py").write_text(VARIANT_MODULE)
    environ = {k: v for k, v in os.environ.items() if k not in ("CONTINUUM_GYM_COMPILE_MESSAGES",
                                                                  "CONTINUUM_GYM_PLUGINS")}
    precompiled = subprocess.run([sys.executable, "-m", "continuum_gym.cli", "precompile", "--import", "mytest_variant",
                                  "--env", "MyTest/PrecompiledTwoSeg-v0"], cwd=tmp_path, env=environ,
                                 capture_output=True, text=True, timeout=1800)
    assert precompiled.returncode == 0, precompiled.stderr[-3000:]
    assert "continuum-gym: compiling mytest_variant.mytest_tracker " in precompiled.stderr  # compiled here, once
    assert "MyTest/PrecompiledTwoSeg-v0" in precompiled.stdout
    environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(tmp_path), environ.get("PYTHONPATH")) if p)
    first = subprocess.run([sys.executable, "-c", FIRST_MAKE], cwd=tmp_path, env=environ, capture_output=True,
                           text=True, timeout=1800)
    assert first.returncode == 0, first.stderr[-3000:]
    assert first.stdout.strip() == "(6,)"  # the 2-segment variant (2 x 2 bends + insertion + endoscope roll)
    assert "compiling" not in first.stderr, first.stderr


@pytest.mark.parametrize("flags, needle", [(["--check"], "--check"), (["--out", "x"], "--out"),
                                           (["--portable"], "--portable")])
def test_precompile_env_refuses_the_flags_of_the_packaged_set(flags, needle, capsys):
    from continuum_gym.cli import main

    assert main(["precompile", "--env", "ContinuumGym/ViewTracking-v0", *flags]) == 2
    err = capsys.readouterr().err
    assert needle in err and "--env" in err

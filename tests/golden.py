"""Golden files: what users rely on, recorded once and compared bit for bit, so no change inside goes unnoticed.

Three records (``tests/data/golden/``):

- ``env_steps.npz``: a few hundred steps of both environments through every front end (single env,
  native vector env, SB3 adapter, threaded batches) at fixed seeds and seeded random actions: obs,
  reward, terminated, truncated and every info value;
- ``reproduce.json``: ``continuum-gym reproduce --json`` (both papers, full size);
- ``evaluate.json``: ``continuum-gym evaluate --json`` on the shipped policies.

``python tests/golden.py`` writes them (only ever before a refactor, or in a commit of its own that
says why they changed); ``tests/test_golden.py`` recomputes and compares. The info layout may change
(nested ``reward_terms`` or flat ``reward_<term>`` keys map to the same canonical name), the values may not.

Bit for bit holds on one *numerics platform*: the last bits of a float result also depend on the CPU's
vector instructions (numpy's SIMD loops, OpenBLAS's LAPACK kernels behind the resolved-rate baseline's
pseudo-inverse, torch's matmul kernels behind the shipped policies) and on those libraries' versions.
The same code on a CPU with other vector instructions (AVX2 against AVX-512) differs from the reference
set by up to 2e-13 in one env case and, through the closed loops of the policies, in the evaluation's
last printed digit; and a CPU with AVX-512, like the reference's, gives exactly the AVX2 results
when its OpenBLAS picks its AVX2 (Haswell) kernels. So a platform
can have its own set, ``platforms/<key>/`` (``python tests/golden.py --platform``, recorded from the
revision that last wrote the reference set, never from the code under test), compared bit for bit.
A platform's set holds only the records that differ from the reference set; the others are read from it
and compared as on a platform without a set (``holds_own``), so a reference record regenerated on purpose
on another platform is checked within the tolerances there until that platform records its own again.
On a platform without its own set, the reference set is compared bit for bit first and, if any bit
differs, within ``CROSS_PLATFORM_TOLERANCE``, with every integer and boolean still exactly equal.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

GOLDEN_DIR = Path(__file__).resolve().parent / "data" / "golden"
PLATFORMS_DIR = GOLDEN_DIR / "platforms"
RECORDS = ("env_steps", "reproduce", "evaluate")
RECORD_FILES = {"env_steps": "env_steps.npz", "reproduce": "reproduce.json", "evaluate": "evaluate.json"}
OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
#: For a platform without its own set: (path fragment, kind, (rtol, atol) or None = not compared), first
#: match wins. Measured between two platforms (an AVX-512 reference, an AVX2-only AMD EPYC): env steps
#: differ by 1.9e-13 at most; the reproduction only in the resolved-rate baseline, whose undamped
#: pseudo-inverse (LAPACK's SVD) near singular configurations turns last-bit differences into other
#: trajectories (case 2 OR 0.6786 / 0.6764, coverage 26.77 / 26.89 %, single grid cells by 0.45); the
#: evaluation through the policies' float32 matmuls and the closed loops by 1.3e-2 relative at most,
#: coverage by 0.9 percentage points. The tolerances are about twice those. The target-point error of the
#: ViewTracking residual (scale 3, not in its reward) is the most sensitive value: on an Ice Lake server (AVX-512,
#: OpenBLAS SkylakeX kernels) its mean moved by 8.4 % and a CI bound by 14 % (a few random-motion episodes end
#: on other trajectories; mean OR by 0.6 %, coverage equal), so it gets a tolerance of its own.
CROSS_PLATFORM_TOLERANCE = {
    "env_steps": (("", "any", (1e-9, 4e-13)),),
    "reproduce": (("resolved_rate", "list", None), ("resolved_rate", "any", (2e-2, 2e-3)),
                  ("", "any", (1e-9, 1e-12))),
    "evaluate": (("coverage_percent", "any", (0.0, 2.0)), ("mean_position_error_m", "any", (0.3, 1e-4)),
                 ("", "any", (3e-2, 1e-4))),
}

#: (case name, env id, front end, number of rows, steps, env kwargs).
ENV_CASES = (
    ("occlusion_default", OCCLUSION, "single", 1, 320, {}),
    ("occlusion_min_norm_random_joint", OCCLUSION, "single", 1, 200,
     {"base_controller": "minimum_norm", "task": "random", "residual_space": "joint", "visibility_guard": None}),
    ("occlusion_pure_mixed", OCCLUSION, "single", 1, 200, {"base_controller": None, "task": "mixed"}),
    ("occlusion_circle_test", OCCLUSION, "single", 1, 120, {"task": "circle", "task_split": "test",
                                                            "lens_model": "physical", "max_bend": 1.2}),
    ("occlusion_vector", OCCLUSION, "vector", 4, 200, {"task": "mixed"}),
    ("occlusion_vector_threaded", OCCLUSION, "vector", 40, 25, {"task": "random"}),
    ("occlusion_sb3", OCCLUSION, "sb3", 3, 160, {}),
    ("view_default", VIEW, "single", 1, 320, {}),
    ("view_rmrc_static_target", VIEW, "single", 1, 200,
     {"base_controller": "resolved_rate", "task": "static", "observe_target": True}),
    ("view_target_space_pan_tilt", VIEW, "single", 1, 200,
     {"residual_space": "target", "task": "pan_tilt", "residual_scale": 1.0,
      "reward_weights": {"overlap_bonus": 1.0}}),
    ("view_pure", VIEW, "single", 1, 200, {"base_controller": None}),
    ("view_rate_limits_case2", VIEW, "single", 1, 150,
     {"task": "case2", "task_split": "test", "rate_limits": [0.05, 1.0, 1.0, 2.0, 1.0, 2.0]}),
    ("view_vector", VIEW, "vector", 4, 200, {"task": "static"}),
    ("view_vector_threaded", VIEW, "vector", 40, 40, {}),
    ("view_sb3", VIEW, "sb3", 3, 160, {}),
)


def canonical_info(info: dict, prefix: str = "") -> dict:
    """Flatten an info dict to {name: array}: nested dicts and named ``reward_terms`` joined by '.',
    flat ``reward_<term>`` keys (older layouts) renamed to ``reward_terms.<term>``; ``_<key>`` masks dropped."""
    out = {}
    for key, value in info.items():
        if key.startswith("_"):
            continue
        name = f"{prefix}{key}"
        if isinstance(value, dict) or callable(getattr(value, "items", None)):  # dicts, named RewardTerms
            out.update(canonical_info(dict(value.items()), f"{name}."))
            continue
        if not prefix and key.startswith("reward_") and key != "reward_terms":
            name = f"reward_terms.{key[len('reward_'):]}"
        out[name] = np.asarray(value)
    return out


def _make(env_id, front_end, rows, kwargs):
    import gymnasium as gym

    import continuum_gym  # noqa: F401

    if front_end == "single":
        return gym.make(env_id, **kwargs)
    if front_end == "vector":
        return gym.make_vec(env_id, num_envs=rows, vectorization_mode="vector_entry_point", **kwargs)
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    return ContinuumSB3VecEnv(env_id, rows, seed=7, **kwargs)


def record_case(env_id, front_end, rows, steps, kwargs, seed=11) -> dict:
    """{name: stacked array} of one case: obs, reward, terminated, truncated and info per step."""
    env = _make(env_id, front_end, rows, kwargs)
    rng = np.random.default_rng([seed, rows, steps])
    # SB3's VecEnv exposes the single action space; Gymnasium's vector env the batched one.
    action_shape = (rows, *env.action_space.shape) if front_end == "sb3" else env.action_space.shape
    record: dict[str, list] = {}

    def add(name, value):
        record.setdefault(name, []).append(np.asarray(value))

    if front_end == "sb3":
        obs = env.reset()
        add("reset_obs", obs)
    else:
        obs, info = env.reset(seed=seed)
        add("reset_obs", obs)
        for key, value in canonical_info(info).items():
            add(f"reset_info.{key}", value)
    for step in range(steps):
        # Beyond [-1, 1] now and then, so clipping is recorded too; an exact zero residual every 7th step.
        action = rng.uniform(-1.2, 1.2, action_shape).astype(np.float32)
        if step % 7 == 0:
            action[:] = 0.0
        if front_end == "sb3":
            env.step_async(action)
            obs, reward, done, infos = env.step_wait()
            add("obs", obs)
            add("reward", reward)
            add("done", done)
            for i, row_info in enumerate(infos):
                for key, value in canonical_info(row_info).items():
                    # terminal_observation and TimeLimit.truncated exist only on the step that ended an episode
                    sparse = key in ("terminal_observation", "TimeLimit.truncated")
                    add(f"row{i}.{key}@{step}" if sparse else f"row{i}.{key}", value)
            continue
        obs, reward, terminated, truncated, info = env.step(action)
        add("obs", obs)
        add("reward", reward)
        add("terminated", terminated)
        add("truncated", truncated)
        for key, value in canonical_info(info).items():
            add(f"info.{key}", value)
        if front_end == "single" and (terminated or truncated):
            obs, info = env.reset()
            add(f"reset_at_{step}", obs)
    env.close()
    return {name: np.stack(values) for name, values in record.items()}


def record_env_steps() -> dict:
    """{"<case>/<name>": array} over every case of ``ENV_CASES``."""
    out = {}
    for name, env_id, front_end, rows, steps, kwargs in ENV_CASES:
        for key, value in record_case(env_id, front_end, rows, steps, kwargs).items():
            out[f"{name}/{key}"] = value
    return out


def run_reproduce() -> dict:
    """``continuum-gym reproduce --json`` (full size), without its wall times."""
    from continuum_gym.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "reproduce.json"
        if main(["reproduce", "--out", tmp, "--json", str(path)]) != 0:
            raise RuntimeError("continuum-gym reproduce failed")
        result = json.loads(path.read_text())
    result.pop("seconds", None)
    return result


def run_evaluate(extra=()) -> dict:
    """``continuum-gym evaluate --json`` on the shipped policies (default episodes and grid)."""
    from continuum_gym.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "evaluate.json"
        if main(["evaluate", "--out", tmp, "--json", str(path), "--no-progress", *extra]) != 0:
            raise RuntimeError("continuum-gym evaluate failed")
        result = json.loads(path.read_text())
    result.pop("metadata", None)  # revision, versions and timings: not results
    return result


def numerics_platform() -> dict:
    """What decides the last bits of a float result besides this code: CPU vector features, the CPU model
    numba compiles for, the kernel set OpenBLAS picked at run time (behind numpy's and scipy's LAPACK), libm,
    torch's kernel level and the versions of the numerical libraries.

    Two CPUs with the same vector features (numpy's list) and library versions can still give other last
    bits (LLVM compiles for the CPU model, and OpenBLAS picks its kernel set per CPU), so the CPU model and
    the BLAS kernels are part of it.
    """
    import platform

    import llvmlite
    import llvmlite.binding
    import numba
    import scipy
    import torch

    try:
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_features__
    return {"machine": platform.machine(), "python": ".".join(platform.python_version_tuple()[:2]),
            "simd": sorted(name for name, present in __cpu_features__.items() if present),
            "llvm_cpu": llvmlite.binding.get_host_cpu_name(),
            "blas_cores": {"numpy": openblas_core(np), "scipy": openblas_core(scipy)},
            "libc": "-".join(platform.libc_ver()),
            "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
            "versions": {"numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
                         "llvmlite": llvmlite.__version__, "torch": torch.__version__}}


def openblas_core(package) -> str:
    """The kernel set (``Haswell``, ``SkylakeX``, ...) the OpenBLAS bundled with a numpy / scipy wheel chose
    on this CPU; "unknown" for another BLAS."""
    import ctypes

    libs = Path(package.__file__).resolve().parent.parent / f"{package.__name__}.libs"
    for library in sorted(libs.glob("lib*openblas*.so*")):
        shared = ctypes.CDLL(str(library))
        for symbol in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
            if hasattr(shared, symbol):
                function = getattr(shared, symbol)
                function.restype = ctypes.c_char_p
                return function().decode()
    return "unknown"


def platform_key(platform: dict) -> str:
    import hashlib

    return hashlib.sha256(json.dumps(platform, sort_keys=True).encode()).hexdigest()[:12]


def write_platform(directory: Path, platform: dict) -> None:
    """platform.json of a platform's set: the fingerprint and the revision the set was recorded from."""
    import subprocess

    revision = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True,
                              text=True, check=False).stdout.strip()
    record = {**platform, "recorded_from": revision or "unknown"}
    (directory / "platform.json").write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")


def golden_set() -> tuple[Path, bool]:
    """(directory, own): this platform's own set if one was recorded, else the reference set."""
    own = PLATFORMS_DIR / platform_key(numerics_platform())
    return (own, True) if (own / "platform.json").is_file() else (GOLDEN_DIR, False)


def holds_own(directory: Path, own: bool, part: str) -> bool:
    """Whether ``part`` is compared as this platform's own record (bit for bit only).

    A record a platform's set does not hold is read from the reference set. When it was left out because
    it equalled the reference bit for bit, the bit-for-bit comparison still applies first; when the
    reference record was regenerated on another platform since (new shipped policies, say), the
    cross-platform tolerances are the meaningful check until ``--platform`` records it here again.
    """
    return own and (directory / RECORD_FILES[part]).is_file()


def record_path(directory: Path, part: str) -> Path:
    """Where ``part`` is stored: a platform's set omits the records equal to the reference set's."""
    path = directory / RECORD_FILES[part]
    return path if path.is_file() or directory == GOLDEN_DIR else GOLDEN_DIR / RECORD_FILES[part]


def load_record(directory: Path, part: str):
    directory = record_path(directory, part).parent
    if part == "env_steps":
        with np.load(directory / "env_steps.npz") as stored:
            return dict(stored)
    return json.loads((directory / f"{part}.json").read_text())


def compute_record(part: str):
    return {"env_steps": record_env_steps, "reproduce": run_reproduce, "evaluate": run_evaluate}[part]()


def record_problems(part: str, expected, actual, own: bool) -> tuple[list, str]:
    """(differences, how compared): bit for bit, then (reference set, another platform) within tolerance."""
    exact = array_differences(expected, actual) if part == "env_steps" else differences(expected, actual)
    if not exact or own:
        return exact, "bit for bit" + (" (this platform's own set)" if own else "")
    rules = CROSS_PLATFORM_TOLERANCE[part]
    close = (array_differences(expected, actual, rules) if part == "env_steps"
             else differences(expected, actual, rules=rules))
    return close, (f"within the cross-platform tolerances {rules} ({len(exact)} values differ in their last "
                   "bits; no golden set of this platform: `python tests/golden.py --platform` records one)")


def largest_difference(part: str, expected, actual) -> tuple[float, float]:
    """(largest absolute, largest relative) difference of the float values of two records."""
    pairs = []
    if part == "env_steps":
        for key, value in expected.items():
            a, b = np.asarray(value, dtype=np.float64).ravel(), np.asarray(actual[key], dtype=np.float64).ravel()
            if a.shape == b.shape and a.size:
                pairs.append((a, b))
    else:
        flat_a, flat_b = [], []
        _flatten_floats(expected, actual, flat_a, flat_b)
        pairs.append((np.array(flat_a), np.array(flat_b)))
    worst_abs = worst_rel = 0.0
    for a, b in pairs:
        finite = np.isfinite(a) & np.isfinite(b)
        diff = np.abs(a[finite] - b[finite])
        if diff.size:
            worst_abs = max(worst_abs, float(diff.max()))
            scale = np.maximum(np.abs(a[finite]), np.abs(b[finite]))
            worst_rel = max(worst_rel, float(np.max(np.where(scale > 0, diff / np.where(scale > 0, scale, 1), 0))))
    return worst_abs, worst_rel


def _flatten_floats(a, b, out_a: list, out_b: list) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in a:
            if key in b:
                _flatten_floats(a[key], b[key], out_a, out_b)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for x, y in zip(a, b):
            _flatten_floats(x, y, out_a, out_b)
    elif isinstance(a, float) and isinstance(b, float):
        out_a.append(a)
        out_b.append(b)


def tolerance_of(rules, path: str, value) -> tuple[float, float] | None | bool:
    """(rtol, atol) of the first rule matching ``path`` (None: not compared); False if there are no rules."""
    if not rules:
        return False
    for fragment, kind, tolerance in rules:
        if fragment in path and (kind == "any" or isinstance(value, list)):
            return tolerance
    return False


def differences(expected, actual, path="", rules=()) -> list:
    """Paths where ``actual`` differs from ``expected``: exactly, or with ``rules`` (see
    ``CROSS_PLATFORM_TOLERANCE``) floats within their tolerance; integers, booleans and strings always
    exactly; extra keys in ``actual`` are additions and allowed."""
    if rules and tolerance_of(rules, path, expected) is None:
        return []
    if isinstance(expected, dict):
        if not isinstance(actual, dict):
            return [f"{path}: expected a dict, got {type(actual).__name__}"]
        found = []
        for key, value in expected.items():
            if key not in actual:
                found.append(f"{path}/{key}: missing")
            else:
                found.extend(differences(value, actual[key], f"{path}/{key}", rules))
        return found
    if isinstance(expected, list):
        if not isinstance(actual, list) or len(actual) != len(expected):
            return [f"{path}: expected a list of {len(expected)}"]
        found = []
        for k, (a, b) in enumerate(zip(expected, actual)):
            found.extend(differences(a, b, f"{path}[{k}]", rules))
        return found
    floats = isinstance(expected, float) and isinstance(actual, float)
    same = expected == actual or (floats and np.isnan(expected) and np.isnan(actual))
    if not same and floats and rules:
        rtol, atol = tolerance_of(rules, path, expected)
        same = abs(expected - actual) <= atol + rtol * abs(expected)
    return [] if same else [f"{path}: {expected!r} != {actual!r}"]


def array_differences(expected: dict, actual: dict, rules=()) -> list:
    """Keys of ``expected`` whose arrays differ from ``actual``'s in shape or any bit of any value (with
    ``rules``, floats within their tolerance; integers and booleans always exactly)."""
    found = []
    for key, value in expected.items():
        if key not in actual:
            found.append(f"{key}: missing")
            continue
        other = np.asarray(actual[key])
        value = np.asarray(value)
        if other.shape != value.shape:
            found.append(f"{key}: shape {value.shape} != {other.shape}")
        elif value.dtype.kind in "fc" or other.dtype.kind in "fc":
            a = value.astype(np.float64)
            b = other.astype(np.float64)
            differ = a.tobytes() != b.tobytes()
            tolerance = tolerance_of(rules, key, value)
            if differ and tolerance is None:
                continue
            if differ and tolerance:
                rtol, atol = tolerance
                differ = not np.allclose(b, a, rtol=rtol, atol=atol, equal_nan=True)
            if differ:
                worst = np.nanmax(np.abs(a - b)) if a.size else 0.0
                found.append(f"{key}: values differ (max |diff| {worst:.3g})")
        elif not np.array_equal(value, other):
            found.append(f"{key}: values differ")
    return found


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=RECORDS, nargs="+", default=RECORDS)
    parser.add_argument("--check", action="store_true", help="compare with the stored files instead of writing")
    parser.add_argument("--platform", action="store_true",
                        help="write this numerics platform's own set (platforms/<key>/) instead of the reference "
                             "set; run it from the revision that wrote the reference set")
    args = parser.parse_args(argv)
    platform = numerics_platform()
    if args.check:
        directory, own = golden_set()
        print(f"platform {platform_key(platform)}: comparing with {directory}")
    else:
        directory = PLATFORMS_DIR / platform_key(platform) if args.platform else GOLDEN_DIR
        directory.mkdir(parents=True, exist_ok=True)
        if args.platform:
            write_platform(directory, platform)
    failed = False
    for part in args.only:
        result = compute_record(part)
        if args.check:
            expected = load_record(directory, part)
            problems, how = record_problems(part, expected, result, holds_own(directory, own, part))
            worst_abs, worst_rel = largest_difference(part, expected, result)
            failed |= bool(problems)
            print(f"{part}: {'identical' if not problems else f'{len(problems)} differences'} ({how}); largest "
                  f"difference {worst_abs:.3g} absolute, {worst_rel:.3g} relative")
            for line in problems[:20]:
                print("   ", line)
        elif args.platform and not record_problems(part, load_record(GOLDEN_DIR, part), result, True)[0]:
            (directory / RECORD_FILES[part]).unlink(missing_ok=True)
            print(f"{part}: equal to the reference set bit for bit, not stored in {directory}")
        elif part == "env_steps":
            np.savez_compressed(directory / "env_steps.npz", **result)
        else:
            (directory / f"{part}.json").write_text(json.dumps(result, indent=1) + "\n")
        if not args.check and (directory / RECORD_FILES[part]).is_file():
            print(f"wrote {part} into {directory}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""What ``continuum-gym train`` is given, checked before anything is written.

A hyperparameter block may hold the keys the trainer reads itself (``RUN_KEYS``) and the keyword
arguments of the algorithm's constructor (``inspect.signature`` of PPO/SAC/TD3 ``__init__``); every
value is checked against the constructor's annotation and, where the algorithm has one, its valid
range. Errors name the key, what is valid and what was given (and the closest key for a misspelling).

YAML 1.1 (PyYAML) reads ``3e-4`` and ``1e6`` as strings (only ``3.0e-4`` is a float), so a numeric
string is accepted where a number is expected; ``64.0`` is accepted where an integer is.
"""

from __future__ import annotations

import inspect
import math
import sys
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from continuum_gym.envs.spec import get_spec, registered_kwargs
from continuum_gym.validation import closest

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

#: The packaged hyperparameter files, ``<algo>.yml``: one block per env id.
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
_NOTED: set = set()  # (hyperparameter file, env id) pairs whose fallback block was announced

# Run keys: read by the trainer, never passed to the algorithm. Expectations are in ``_RUN_RULES``.
RUN_KEYS = ("n_timesteps", "n_envs", "env_kwargs", "residual_scale", "burn_in_steps", "eval_freq", "n_eval_episodes",
            "checkpoint_freq", "checkpoint_minutes", "keep_checkpoints", "policy", "action_noise_std",
            "normalize_reward", "helpers")
# Constructor arguments the trainer sets itself; a hyperparameter file may not.
TRAINER_SET = {"self": "", "env": "the environment comes from --env", "seed": "use --seed",
               "verbose": "set by the trainer", "device": "training runs on the CPU",
               "tensorboard_log": "logs go to the run directory's tb/", "_init_setup_model": "set by SB3"}
# Hyperparameters that may be given as rl-zoo's linear schedules, "lin_<initial value>".
SCHEDULE_KEYS = ("learning_rate", "clip_range")
MAX_SEED = 2**32 - 1  # numpy's legacy seeding, which SB3 uses, takes 32 bits


class _Invalid(Exception):
    """A value that does not fit; the caller phrases the message."""


def _as_int(value) -> int:
    if isinstance(value, bool):
        raise _Invalid
    if isinstance(value, int):
        return value
    number = _as_float(value)
    if not math.isfinite(number) or not number.is_integer():
        raise _Invalid
    return int(number)


def _as_float(value, infinite: bool = False) -> float:
    if isinstance(value, bool):
        raise _Invalid
    if isinstance(value, (int, float)):
        number = float(value)
    elif isinstance(value, str):
        try:
            number = float(value.strip())
        except ValueError:
            raise _Invalid from None
    else:
        raise _Invalid
    if math.isnan(number) or (math.isinf(number) and not infinite):
        raise _Invalid
    return number


def _whole(minimum: int, note: str = "") -> tuple[str, Callable]:
    def convert(value):
        number = _as_int(value)
        if number < minimum:
            raise _Invalid
        return number

    return f"a whole number >= {minimum}{note}", convert


def _number(low=None, high=None, low_open=False, infinite=False, note="") -> tuple[str, Callable]:
    def convert(value):
        number = _as_float(value, infinite)
        if low is not None and (number < low or (low_open and number == low)):
            raise _Invalid
        if high is not None and number > high:
            raise _Invalid
        return number

    if low is not None and high is not None:
        bounds = f" in {'(' if low_open else '['}{low:g}, {high:g}]"
    elif low is not None:
        bounds = f" {'>' if low_open else '>='} {low:g}"
    else:
        bounds = ""
    return f"a {'' if infinite else 'finite '}number{bounds}{note}", convert


def _flag() -> tuple[str, Callable]:
    def convert(value):
        if not isinstance(value, bool):
            raise _Invalid
        return value

    return "true or false", convert


def _mapping() -> tuple[str, Callable]:
    def convert(value):
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise _Invalid
        return value

    return "a mapping (or empty)", convert


def schedule_initial(value: object, name: str) -> float:
    """The initial value of a number or ``lin_<x>`` schedule; ``ValueError`` naming ``name`` otherwise."""
    text = value[4:] if isinstance(value, str) and value.startswith("lin_") else value
    try:
        initial = _as_float(text)
    except _Invalid:
        raise ValueError(f"{name} must be a number or 'lin_<initial value>'; got {value!r}") from None
    if not initial > 0:
        raise ValueError(f"{name}: the initial value of {value!r} must be > 0")
    return initial


def _schedule(name: str) -> tuple[str, Callable]:
    def convert(value):
        initial = schedule_initial(value, name)
        return value if isinstance(value, str) and value.startswith("lin_") else initial

    return "a number > 0 or 'lin_<initial value>'", convert


def _train_freq() -> tuple[str, Callable]:
    def convert(value):
        if isinstance(value, (list, tuple)):
            if len(value) != 2 or value[1] not in ("step", "episode"):
                raise _Invalid
            return [_whole(1)[1](value[0]), value[1]]
        return _whole(1)[1](value)

    return "a whole number >= 1 or [n, 'step' | 'episode']", convert


def _auto_or_number(prefix_ok: bool) -> tuple[str, Callable]:
    def convert(value):
        if isinstance(value, str) and (value == "auto" or (prefix_ok and value.startswith("auto_"))):
            if value != "auto":
                _number(0.0, low_open=True)[1](value[5:])
            return value
        return _number(0.0 if prefix_ok else None)[1](value)

    if prefix_ok:
        return "'auto', 'auto_<initial value > 0>' or a number >= 0", convert
    return "'auto' or a number", convert


def _helper_list(value: Any) -> list:
    """``helpers``: a list of names (checked against the env's helpers where the env is known: ``train``)."""
    if not isinstance(value, list) or not all(isinstance(name, str) for name in value):
        raise _Invalid
    return value


_RUN_RULES: dict[str, tuple[str, Callable]] = {
    "n_timesteps": _whole(1), "n_envs": _whole(1), "env_kwargs": _mapping(),
    "residual_scale": _number(0.0, low_open=True), "burn_in_steps": _whole(0), "eval_freq": _whole(1),
    "n_eval_episodes": _whole(1), "checkpoint_freq": _whole(1),
    "checkpoint_minutes": _number(0.0, low_open=True, infinite=True, note=" (.inf: by steps only)"),
    "keep_checkpoints": _whole(1), "action_noise_std": _number(0.0), "normalize_reward": _flag(),
    "helpers": ("a list of the env's helper names (envs/helpers.py)", _helper_list),
}



_ALGO_RULES = {
    "learning_rate": _schedule("learning_rate"), "clip_range": _schedule("clip_range"),
    "clip_range_vf": _number(0.0, low_open=True), "n_steps": _whole(1), "batch_size": _whole(1),
    "n_epochs": _whole(1), "gamma": _number(0.0, 1.0), "gae_lambda": _number(0.0, 1.0), "vf_coef": _number(0.0),
    "max_grad_norm": _number(0.0, low_open=True), "sde_sample_freq": _whole(-1, " (-1: once per rollout)"),
    "target_kl": _number(0.0, low_open=True), "stats_window_size": _whole(1), "buffer_size": _whole(1),
    "learning_starts": _whole(0), "tau": _number(0.0, 1.0, low_open=True), "train_freq": _train_freq(),
    "gradient_steps": _whole(-1, " (-1: one per collected step)"), "target_update_interval": _whole(1),
    "policy_delay": _whole(1), "target_policy_noise": _number(0.0), "target_noise_clip": _number(0.0),
}
_PER_ALGO_RULES = {
    "ppo": {"ent_coef": _number(0.0)},
    "sac": {"ent_coef": _auto_or_number(True), "target_entropy": _auto_or_number(False)},
}


def _members(hint) -> tuple:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return typing.get_args(hint)
    return (hint,)


def _conform(value, hint):
    """``value`` fitted to an annotation (numeric strings and integral floats converted); ``_Invalid`` if it cannot."""
    if hint is inspect.Parameter.empty or hint is Any:
        return value
    members = _members(hint)
    if value is None:
        if type(None) in members:
            return None
        raise _Invalid
    for wanted in (bool, int, float, str):  # exact matches first: a str never becomes a float if str is valid
        if wanted in members and type(value) is wanted:
            return value
    if int in members and float not in members:
        return _as_int(value)
    if float in members:
        return _as_float(value)
    if any(typing.get_origin(m) is dict or m is dict for m in members) and isinstance(value, dict):
        return value
    for member in members:
        if typing.get_origin(member) is tuple and isinstance(value, (list, tuple)):
            args = typing.get_args(member)
            if len(args) == len(value):
                return [_conform(item, arg) for item, arg in zip(value, args)]
    raise _Invalid


def _describe(hint) -> str:
    names = {bool: "true or false", int: "a whole number", float: "a number", str: "a string", type(None): "null"}
    parts = []
    for member in _members(hint):
        if member in names:
            parts.append(names[member])
        elif typing.get_origin(member) is dict or member is dict:
            parts.append("a mapping")
        elif typing.get_origin(member) is tuple:
            parts.append("a list [" + ", ".join(_describe(arg) for arg in typing.get_args(member)) + "]")
        elif typing.get_origin(member) is type:
            parts.append(f"a Python class ({_name(typing.get_args(member)[0])}; not settable from YAML)")
        else:
            parts.append(f"a Python object ({_name(member)}; not settable from YAML)")
    return " or ".join(dict.fromkeys(parts))


def _name(thing) -> str:
    return getattr(thing, "__name__", None) or str(thing)


def algorithm_parameters(cls: type[BaseAlgorithm]) -> dict[str, inspect.Parameter]:
    """Keyword arguments of ``cls.__init__`` a hyperparameter file may set."""
    return {name: p for name, p in inspect.signature(cls.__init__).parameters.items() if name not in TRAINER_SET}


def check_hyperparams(block: dict, cls: type[BaseAlgorithm], algo: str, source: str) -> dict:
    """A checked copy of a hyperparameter block (values converted where YAML typed them loosely).

    Raises ``ValueError`` ``"<source>: <key> must be <valid>; got <value>"`` for the first bad entry.
    """
    parameters = algorithm_parameters(cls)
    valid = sorted(set(parameters) | set(RUN_KEYS))
    rules = {**_ALGO_RULES, **_PER_ALGO_RULES.get(algo, {}), **_RUN_RULES}
    checked: dict[str, Any] = {}
    for key, value in block.items():
        if not isinstance(key, str):
            raise ValueError(f"{source}: hyperparameter names must be strings; got {key!r}")
        if key in TRAINER_SET:
            why = TRAINER_SET[key] or "internal"
            raise ValueError(f"{source}: {key!r} cannot be set in a hyperparameter file ({why}); got {value!r}")
        if key not in valid:
            raise ValueError(f"{source}: unknown hyperparameter {key!r} for {algo}{closest(key, valid)}; "
                             f"valid: {valid}")
        if key == "policy":
            if not isinstance(value, str) or value not in cls.policy_aliases:
                raise ValueError(f"{source}: policy must be one of {sorted(cls.policy_aliases)}; got {value!r}")
            checked[key] = value
            continue
        if key == "action_noise_std" and algo != "td3":
            raise ValueError(f"{source}: action_noise_std is read for td3 only (got it for {algo}); remove it")
        hint = parameters[key].annotation if key in parameters else inspect.Parameter.empty
        if value is None and key in parameters and type(None) in _members(hint):
            checked[key] = None
            continue
        expect, convert = rules.get(key) or (_describe(hint), lambda v, h=hint: _conform(v, h))
        try:
            checked[key] = convert(value)
        except _Invalid:
            raise ValueError(f"{source}: {key} must be {expect}; got {value!r}") from None
        except ValueError as error:
            raise ValueError(f"{source}: {error}") from None
    return checked


def check_combination(algo: str, hp: dict, n_envs: int, source: str) -> None:
    """Constraints between keys that SB3 would otherwise assert on mid-construction."""
    if algo == "ppo" and hp.get("normalize_advantage", True):
        if hp.get("batch_size", 64) < 2:
            raise ValueError(f"{source}: batch_size must be >= 2 with normalize_advantage (the default); "
                             f"got {hp['batch_size']}")
        if hp.get("n_steps", 2048) * n_envs < 2:
            raise ValueError(f"{source}: n_steps * n_envs must be >= 2 with normalize_advantage; got "
                             f"{hp.get('n_steps', 2048)} * {n_envs}")


def check_budget(cls: type[BaseAlgorithm], hp: dict, total: int, residual: bool, source: str,
                 budget: str = "--steps") -> str | None:
    """``ValueError`` when ``total`` steps would train nothing; a warning (returned) when they train the actor little.

    A residual run holds its actor at the initial weights (the base controller's command) for its first
    ``burn_in_steps`` steps, and an off-policy learner takes no gradient step before ``learning_starts``:
    a budget at or below either ends with the policy it started from. ``budget`` names where ``total`` came from.
    """
    idle = {}
    if residual and int(hp.get("burn_in_steps", 0)):
        idle["burn_in_steps"] = (int(hp["burn_in_steps"]), "the actor is held at the base controller's command")
    parameter = algorithm_parameters(cls).get("learning_starts")  # off-policy learners only
    starts = hp.get("learning_starts", parameter.default if parameter is not None else 0)
    if isinstance(starts, int) and starts > 0:
        idle["learning_starts"] = (starts, "no gradient step is taken")
    if not idle:
        return None
    held = max(value for value, _ in idle.values())
    binding = {key: value for key, value in idle.items() if value[0] >= min(total, held)}
    what = " and ".join(f"{key}: {value} ({why} for the first {value} steps)" for key, (value, why) in binding.items())
    if total <= held:
        raise ValueError(f"{budget} {total} trains nothing with {source}: {what}. Pass --steps above {held}, or "
                         f"lower {' and '.join(binding)} in your own copy of the block (--hyperparams FILE; "
                         "docs/configure.md)")
    if total - held < held:
        return (f"only the last {total - held} of {total} steps train the actor with {source}: {what}; a larger "
                f"--steps, or a lower {' / '.join(binding)} in --hyperparams FILE, trains it for longer")
    return None


def whole_number(name: str, value: object, minimum: int = 1, maximum: int | None = None) -> int:
    """``value`` (an int, an integral float or such a string) as an int in [minimum, maximum], else ``ValueError``."""
    try:
        number = _as_int(value)
    except _Invalid:
        number = None
    if number is None or number < minimum or (maximum is not None and number > maximum):
        bounds = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        raise ValueError(f"{name} must be a finite whole number {bounds}; got {value!r}")
    return number


def seed_number(name: str, value: object) -> int:
    return whole_number(name, value, 0, MAX_SEED)


def output_directory(name: str, out: Path | str) -> Path:
    """``out`` as a path that is, or can become, a directory."""
    path = Path(out)
    for parent in (path, *path.parents):
        if parent.exists():
            if not parent.is_dir():
                given = "" if parent == path else f" (got {str(out)!r})"
                raise ValueError(f"{name} must be a directory; {str(parent)!r} is an existing file{given}")
            break
    return path


def hyperparams_file(path: Path | str) -> Path:
    """``path``, or the packaged file of that bare name (``ppo_pixels.yml``) when no such file is here."""
    path = Path(path)
    if not path.exists() and path.name == str(path) and (HYPERPARAMS_DIR / path.name).is_file():
        return HYPERPARAMS_DIR / path.name
    return path


def load_hyperparams(algo: str, env_id: str, path: Path | str | None = None) -> dict:
    """The block for ``env_id`` in ``<algo>.yml`` (anchors resolved), unchecked; a bad file raises ``ValueError``.

    ``path`` names another file, or a packaged one by its bare name (``ppo_pixels.yml``)."""
    path = hyperparams_file(path) if path else HYPERPARAMS_DIR / f"{algo}.yml"
    if not path.is_file():
        raise ValueError(f"--hyperparams: no file {str(path)!r}" + (" (it is a directory)" if path.is_dir() else ""))
    try:
        table = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ValueError(f"{path} is not valid YAML ({getattr(error, 'problem', None) or error}{where})") from None
    if table is None:
        raise ValueError(f"{path} is empty; expected a mapping of env id to a block of hyperparameters")
    if not isinstance(table, dict):
        raise ValueError(f"{path} must map env ids to blocks of hyperparameters; got a {type(table).__name__}")
    key = env_id
    if env_id not in table:
        blocks = sorted(str(k) for k in table if k != "default")
        base_id = get_spec(env_id).env_id
        if base_id == env_id or base_id not in table:
            raise ValueError(f"{path.name} has no block for {env_id!r}; blocks: {blocks}")
        key = base_id  # a user's registered id trains with its library env's block
    block = table[key]
    if not isinstance(block, dict):
        raise ValueError(f"{path}: the block for {key!r} must be a mapping of hyperparameters; got {block!r}")
    block = dict(block)
    if key != env_id:
        registered = registered_kwargs(env_id)
        kept = {k: v for k, v in dict(block.get("env_kwargs") or {}).items() if k not in registered}
        block["env_kwargs"] = kept
        if (str(path), env_id) not in _NOTED:  # said once per process, however often the block is read
            _NOTED.add((str(path), env_id))
            print(f"note: {path.name} has no block for {env_id!r}; using the block of {key!r}, with the env keywords "
                  f"{env_id!r} was registered with taking precedence (your own: --hyperparams FILE; the format is in "
                  "docs/configure.md)", file=sys.stderr)
    return block

"""Fuzz every constructor keyword and CLI flag with wrong types, NaN/inf, out-of-range and unknown values.

Each must be refused by the library's own error, naming the parameter: a ``ValueError`` (the library's
errors derive from it) from a constructor, exit status 2 with a ``continuum-gym <command>:`` message from
the CLI. Never a bare ``TypeError`` / ``ZeroDivisionError`` or a traceback, and never a silently
accepted value that starts a job (a SIGALRM guard fails the case if a command starts running).
"""

from __future__ import annotations

import math
import signal

import gymnasium as gym
import numpy as np
import pytest

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.cli import main
from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.envs.view_tracking.config import ViewTrackingConfig

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
BAD_VALUES = ["abc", math.nan, math.inf, -math.inf, -1, 1e308, [1, 2, 3], {"x": 1}, object()]
FRONT_END = ("render_mode", "camera", "pixel_occlusion")
#: Keywords gym.make itself reads before the constructor (TimeLimit, render-mode wrappers): Gymnasium's
#: own checks answer there, so these are fuzzed on the env class, which the entry point calls.
GYM_MAKE_KEYWORDS = ("render_mode", "max_episode_steps")


def keywords(config_class):
    return [name for name in config_class.keyword_names() if name not in ("config",)]


CASES = [(OCCLUSION, name) for name in keywords(OcclusionConfig)] + [(VIEW, name) for name in keywords(ViewTrackingConfig)]
CASES += [(env_id, name) for env_id in (OCCLUSION, VIEW) for name in FRONT_END]


@pytest.mark.parametrize("env_id,keyword", CASES, ids=lambda x: x.split("/")[-1] if "/" in str(x) else str(x))
def test_every_constructor_keyword_refuses_bad_values_by_name(env_id, keyword):
    accepted = []
    for value in BAD_VALUES:
        try:
            if keyword in GYM_MAKE_KEYWORDS:
                env = _entry_point(env_id)(**{keyword: value})
            else:
                env = gym.make(env_id, **{keyword: value})
        except ValueError as error:  # the library's own errors (UnknownArgumentError is one too)
            assert keyword.split("_")[0] in str(error), f"{keyword}={value!r}: message does not name it: {error}"
            continue
        except Exception as error:  # noqa: BLE001  (anything else is the failure this test looks for)
            pytest.fail(f"{keyword}={value!r} raised a bare {type(error).__name__}: {error}")
        # A value the library accepts must give a working, finite environment.
        obs, _ = env.reset(seed=0)
        obs, reward, *_ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert np.all(np.isfinite(obs)) and np.isfinite(reward), f"{keyword}={value!r}"
        accepted.append(value)
    assert len(accepted) <= 2, f"{keyword} accepted {accepted!r}"  # at most the few that mean something (1e308 s...)


def _entry_point(env_id):
    from gymnasium.envs.registration import load_env_creator

    return load_env_creator(gym.spec(env_id).entry_point)


def test_unknown_keywords_and_missing_values_are_named():
    with pytest.raises(ValueError, match="unexpected keyword argument 'max_bnd'.*max_bend"):
        gym.make(OCCLUSION, max_bnd=1.0)
    for keyword in ("residual_scale", "control_dt", "substeps", "task"):
        with pytest.raises(ValueError, match=keyword):
            gym.make(VIEW, **{keyword: None})


REQUIRED = {
    "train": ["--env", VIEW, "--algo", "ppo", "--steps", "64"],
    "evaluate": ["--env", VIEW, "--episodes", "1", "--grid", "2"],
    "optimum": ["--env", VIEW, "--task", "coverage"],
    "render": ["--env", VIEW, "--steps", "2"],
    "sweep": ["--env", VIEW, "--steps", "64"],
    "dataset": ["--env", VIEW, "--episodes", "1"],
    "reproduce": ["--quick"],
}
FLAG_VALUES = {
    "train": {"--seed": ["abc", "-5", "nan"], "--parallel": ["0", "abc"], "--steps": ["0", "-5", "inf", "nan", "abc"],
              "--n-envs": ["0", "-1", "abc"], "--algo": ["nope"], "--base": ["nope"], "--env": ["nope"],
              "--hyperparams": ["/nonexistent.yml"]},
    "evaluate": {"--episodes": ["0", "-1", "abc"], "--grid": ["0", "abc", "-3"], "--env": ["nope"],
                 "--split": ["train", "nope"], "--env-kwargs": ["{", "[1]", '{"max_bend": 100}'],
                 "--policy": ["nope", "no_such_module:f", "math:nope"], "--policies": ["/nonexistent"],
                 "--model-error": ["huge", "1", ""]},
    "optimum": {"--grid": ["0", "abc"], "--workers": ["0", "abc"], "--n-starts": ["0", "-1"], "--seed": ["-5", "abc"],
                "--global-check": ["-1", "abc"], "--env-hold-tasks": ["0", "abc"], "--task": ["nope"],
                "--env": ["nope"]},
    "render": {"--seed": ["-5", "abc"], "--steps": ["0", "-1", "abc"], "--size": ["0", "-5", "abc", "100000"],
               "--every": ["0", "abc"], "--env": ["nope"], "--policy": ["nope"], "--task": ["nope"]},
    "sweep": {"--seeds": ["-1", "abc"], "--steps": ["0", "nan", "inf", "-5", "abc"], "--cpus-per-trial": ["0", "nan", "-1"],
              "--algo": ["nope"], "--env": ["nope"], "--search": ["/nonexistent.yml"]},
    "dataset": {"--episodes": ["0", "-1", "abc"], "--noise": ["nan", "inf", "-1"], "--seed": ["-5", "abc"],
                "--env": ["nope"], "--controller": ["nope"], "--split": ["nope"]},
    "reproduce": {"--grid": ["0", "-1", "abc"]},
}
FLAG_VALUES["render"].update({"--supersample": ["0", "abc"], "--gap": ["-1", "abc"], "--elevation": ["90", "nan"],
                              "--distance": ["0", "nan"]})
for _flags in FLAG_VALUES.values():  # every subcommand imports plug-in modules first, and names a bad one
    _flags["--import"] = ["no_such_module_xyz", "1bad.name"]
CLI_CASES = [(command, flag, value) for command, flags in FLAG_VALUES.items() for flag, values in flags.items()
             for value in values]


class Started(Exception):
    pass


def _alarm(signum, frame):
    raise Started("the command started running with the bad value")


@pytest.mark.parametrize("command,flag,value", CLI_CASES, ids=lambda x: str(x))
def test_every_cli_flag_refuses_bad_values_with_exit_2(command, flag, value, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = [command, *REQUIRED[command]]
    if flag in argv:
        index = argv.index(flag)
        argv[index + 1] = value
    else:
        argv += [flag, value]
    argv += {"dataset": ["--root", str(tmp_path / "data")], "render": ["--out", str(tmp_path / "out.gif")]}.get(
        command, ["--out", str(tmp_path / "out")])
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(20)
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own refusal
        code = exit_.code
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    err = capsys.readouterr().err
    assert code == 2, f"{argv}: exit {code}\n{err[-1500:]}"
    assert f"continuum-gym {command}" in err and "Traceback" not in err, err[-1500:]
    assert flag.lstrip("-").split("-")[0] in err.replace("_", "-"), f"{flag} not named: {err[-800:]}"

"""``continuum-gym sweep --address``: a sweep of a registered variant (examples/my_lab) on a local
``ray start --head`` that uses token authentication, run as a user would run it; and the error that says what
a cluster needs when the connection fails, at once rather than after Ray's retries."""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest
import yaml

from continuum_gym.agents import cluster as cluster_module
from continuum_gym.agents import sweep as sweep_module
from continuum_gym.cli import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
BASE = "ContinuumGym/OcclusionAvoidance-v0"
MY_ID = "MyLab/Occlusion2Seg-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
RAY = Path(sys.executable).parent / "ray"
#: What a new shell has none of: the test decides each of them.
RAY_VARS = ("CONTINUUM_GYM_PLUGINS", "RAY_ADDRESS", "RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH")


def _free_ports(n: int) -> list[int]:
    sockets = [socket.socket() for _ in range(n)]
    try:
        for sock in sockets:
            sock.bind(("127.0.0.1", 0))
        return [sock.getsockname()[1] for sock in sockets]
    finally:
        for sock in sockets:
            sock.close()


def _shell_env(home: Path, **changes) -> dict:
    """The environment of a new shell of a user whose home is ``home``."""
    env = {k: v for k, v in os.environ.items() if k not in RAY_VARS}
    env["HOME"] = str(home)
    env.update(changes)
    return env


def _session_members(sid: int) -> list[int]:
    """Pids of the processes of session ``sid`` (the head's processes, workers included)."""
    pids = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[3]) == sid:
                pids.append(int(proc.name))
    return pids


@contextmanager
def ray_head(home: Path, cwd: Path):
    """``ray start --head --block`` in a session of its own; yields its GCS port. Afterwards the head and every
    process of its session are ended by pid (``ray stop`` would end every Ray of this machine)."""
    port, client, dashboard, agent = _free_ports(4)
    temp = Path(tempfile.mkdtemp(prefix="cg-ray-", dir="/tmp"))  # short: Ray's socket paths live under it
    log_path = temp / "head.log"
    command = [str(RAY), "start", "--head", f"--port={port}", "--num-cpus=2", "--disable-usage-stats",
               "--include-dashboard=false", f"--dashboard-port={dashboard}", f"--ray-client-server-port={client}",
               f"--dashboard-agent-listen-port={agent}", f"--temp-dir={temp}", "--block"]
    with open(log_path, "w") as log:
        head = subprocess.Popen(command, env=_shell_env(home), cwd=cwd, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
    try:
        deadline = time.time() + 180
        while "Ray runtime started" not in log_path.read_text():
            assert head.poll() is None, f"ray start --head exited:\n{log_path.read_text()[-3000:]}"
            assert time.time() < deadline, f"ray start --head did not start:\n{log_path.read_text()[-3000:]}"
            time.sleep(0.5)
        yield port
    finally:
        head.send_signal(signal.SIGTERM)  # --block: the head ends the processes it started
        try:
            head.wait(timeout=30)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()
        deadline = time.time() + 15
        while _session_members(head.pid) and time.time() < deadline:
            time.sleep(0.5)
        for pid in _session_members(head.pid):  # anything left behind (a worker): by pid
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        shutil.rmtree(temp, ignore_errors=True)


@pytest.mark.slow
def test_a_sweep_of_a_registered_variant_runs_on_a_token_authenticated_cluster(tmp_path):
    # The head and the user share a home with a token (as after any local Ray run): Ray 2.60's
    # `ray start --head` then requires it. The head knows nothing of my_lab: not on its path, no
    # CONTINUUM_GYM_PLUGINS; the sweep passes them to the trial's worker.
    home = tmp_path / "home"
    (home / ".ray").mkdir(parents=True)
    (home / ".ray" / "auth_token").write_text(secrets.token_hex(32))
    hyperparams = tmp_path / "tiny.yml"
    hyperparams.write_text(f"{BASE}:\n  n_envs: 4\n  n_steps: 16\n  batch_size: 32\n  n_epochs: 1\n"
                           "  eval_freq: 64\n  n_eval_episodes: 2\n  checkpoint_freq: 1000\n"
                           "  env_kwargs: {task: hold, visibility_guard: 0.5}\n")
    out = tmp_path / "sweeps"
    user_path = os.pathsep.join(p for p in (str(EXAMPLES), os.environ.get("PYTHONPATH")) if p)
    (tmp_path / "head").mkdir()
    (tmp_path / "stranger").mkdir()
    with ExitStack() as stack:
        port = stack.enter_context(ray_head(home, tmp_path / "head"))
        address = f"127.0.0.1:{port}"
        command = [sys.executable, "-m", "continuum_gym.cli", "sweep", "--import", "my_lab.plugins", "--env", MY_ID,
                   "--address", address, "--seeds", "0", "--steps", "128", "--hyperparams", str(hyperparams),
                   "--out", str(out)]
        # Without the token (another home): refused at once, saying what a cluster needs.
        start = time.time()
        refused = subprocess.run(command, env=_shell_env(tmp_path / "stranger", PYTHONPATH=user_path), cwd=ROOT,
                                 capture_output=True, text=True, timeout=300)
        refused_after = time.time() - start
        assert refused.returncode == 2, refused.stderr[-3000:]
        message = refused.stderr
        assert f"could not connect to the Ray cluster at {address}: the cluster rejected" in message
        assert "set RAY_AUTH_MODE=token" in message and "`ray get-auth-token` on the head" in message
        assert "~/.ray/auth_token" in message and "RAY_AUTH_TOKEN_PATH" in message
        assert "plug-in modules (my_lab.plugins) must be importable on every node" in message
        assert refused_after < 60  # Ray alone retries a rejected token for 20 s after its own start-up
        assert not out.exists()
        # With it (~/.ray/auth_token, RAY_AUTH_MODE unset): the sweep connects in token mode, as Ray's CLI does.
        result = subprocess.run(command, env=_shell_env(home, PYTHONPATH=user_path), cwd=ROOT, capture_output=True,
                                text=True, timeout=600)
        assert result.returncode == 0, result.stderr[-3000:]
        assert "connecting with RAY_AUTH_MODE=token" in result.stderr
    (run,) = list(out.glob("Occlusion2Seg_ppo_mylab_dls/trials/*/Occlusion2Seg_ppo_mylab_dls_seed0"))
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["base_controller"] == "mylab_dls"
    assert config["env_config"]["base_controller"] == "my_lab.plugins:mylab_dls"
    assert config["env_config"]["robot"]["lengths"] == [0.030, 0.025]
    assert (run / "model.zip").is_file()


def test_an_address_where_nothing_listens_fails_at_once_saying_what_a_cluster_needs(tmp_path, monkeypatch, capsys):
    pytest.importorskip("ray")
    for name in RAY_VARS:  # set, then removed: whatever the sweep sets is undone after the test
        monkeypatch.setenv(name, "x")
        monkeypatch.delenv(name)
    monkeypatch.setenv("HOME", str(tmp_path))  # no token
    hyperparams = tmp_path / "hp.yml"
    hyperparams.write_text(yaml.safe_dump({VIEW: {"n_envs": 4, "n_timesteps": 64}}))
    (port,) = _free_ports(1)  # closed again: nothing listens there
    start = time.time()
    code = main(["sweep", "--env", VIEW, "--address", f"127.0.0.1:{port}", "--hyperparams", str(hyperparams),
                 "--out", str(tmp_path / "out")])
    assert code == 2 and time.time() - start < 30  # ray.init alone waits minutes
    err = capsys.readouterr().err
    assert f"continuum-gym sweep: could not connect to the Ray cluster at 127.0.0.1:{port}: nothing accepts " \
           "connections" in err
    assert "RAY_AUTH_MODE=token" in err and "ray get-auth-token" in err and "RAY_AUTH_TOKEN" in err
    assert "importable on every node" in err and "same continuum-gym version" in err
    assert not (tmp_path / "out").exists()
    import ray

    assert not ray.is_initialized()


def test_the_trials_runtime_env_carries_the_plugin_modules_and_their_path(monkeypatch):
    monkeypatch.delenv("CONTINUUM_GYM_PLUGINS", raising=False)
    monkeypatch.setenv("PYTHONPATH", "/labs/code")
    assert sweep_module.trial_runtime_env() == {}  # nothing registered: the cluster's own environment
    monkeypatch.setenv("CONTINUUM_GYM_PLUGINS", "my_lab.plugins,,other.mod")
    env_vars = sweep_module.trial_runtime_env()["env_vars"]
    assert env_vars["CONTINUUM_GYM_PLUGINS"] == "my_lab.plugins,other.mod"
    assert env_vars["PYTHONPATH"] == os.pathsep.join(["/labs/code", "${PYTHONPATH}"])  # ahead of the node's own
    assert cluster_module._host_port("ray://head:10001") == ("head", 10001)
    assert cluster_module._host_port("auto") is None

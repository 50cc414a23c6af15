"""Checkpoint units: everything needed to continue a run, written as one verifiable, atomic directory.

Layout of ``<run>/checkpoints/``::

    step_000000016000/       one unit: the run as it was after 16 000 environment steps
        model.zip            SB3 model (policy, optimiser state, step count)
        replay_buffer.pkl    off-policy learners only
        vecnormalize.pkl     when reward normalisation is on
        burn_in_actor.pt     while actor burn-in is not over: the initial actor it keeps restoring
        state.json           num_timesteps, wall time, evaluation history, burn-in progress
        manifest.json        sha256 and size of every file above; written last
    .tmp-step_.../           a unit being written, or left by a kill: never read, removed on start

A unit is written into ``.tmp-step_<n>/``, each file fsynced, the manifest written last, the directory
fsynced and renamed into place, then the parent fsynced: a reader sees the whole unit or none of it.
A unit is *verified* when its manifest parses and every size and checksum matches; ``find_resumable``
returns the newest verified unit and the damaged ones above it. The last ``keep`` units are kept, so a
damaged newest unit has a fallback.

Runs written before units existed kept one set of files beside each other (``checkpoints/latest.zip``,
``replay_buffer.pkl``, ``vecnormalize.pkl``, ``state.json``); ``legacy_unit`` reads that layout
(unverifiable: it has no manifest).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.type_aliases import GymEnv

from continuum_gym.evaluation.io import fsync_directory, temporary_files

CHECKPOINTS = "checkpoints"
MODEL = "model.zip"
REPLAY_BUFFER = "replay_buffer.pkl"
NORMALIZER = "vecnormalize.pkl"
BURN_IN_ACTOR = "burn_in_actor.pt"
STATE = "state.json"
MANIFEST = "manifest.json"
PREFIX = "step_"
TMP_PREFIX = ".tmp-"
FORMAT = 1
LEGACY_MODEL = "latest.zip"
LEGACY_FILES = (LEGACY_MODEL, REPLAY_BUFFER, NORMALIZER, STATE)

#: Writes one file of a unit at the path it is given.
Writer = Callable[[Path], None]


@dataclass(frozen=True)
class Unit:
    """One checkpoint: its directory and the environment step it was taken at."""

    path: Path
    step: int
    legacy: bool = False

    def file(self, name: str) -> Path | None:
        """The unit's file ``name`` (e.g. ``MODEL``) if it has one."""
        if self.legacy and name == MODEL:
            name = LEGACY_MODEL
        path = self.path / name
        return path if path.is_file() else None

    def state(self) -> dict:
        """``state.json``: at least ``num_timesteps``."""
        return json.loads((self.path / STATE).read_text())


def unit_name(step: int) -> str:
    return f"{PREFIX}{int(step):012d}"


def list_units(folder: Path | str) -> list[Unit]:
    """Published units in ``folder``, oldest first (temporary directories are not units)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    units = []
    for path in folder.iterdir():
        digits = path.name[len(PREFIX):]
        if path.is_dir() and path.name.startswith(PREFIX) and digits.isdigit():
            units.append(Unit(path, int(digits)))
    return sorted(units, key=lambda unit: unit.step)


def verify(unit: Unit) -> str | None:
    """``None`` if the unit is complete and intact, else what is wrong with it."""
    try:
        manifest = json.loads((unit.path / MANIFEST).read_text())
        files = manifest["files"]
        step = manifest["step"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        return f"{MANIFEST} missing or unreadable ({type(error).__name__})"
    if step != unit.step:
        return f"{MANIFEST} is for step {step}, the directory for step {unit.step}"
    for required in (MODEL, STATE):
        if required not in files:
            return f"{MANIFEST} does not list {required}"
    for name, entry in files.items():
        path = unit.path / name
        if not path.is_file():
            return f"{name} is missing"
        size = path.stat().st_size
        if size != entry.get("bytes"):
            return f"{name} has {size} bytes, the manifest says {entry.get('bytes')}"
        if _sha256(path) != entry.get("sha256"):
            return f"{name} does not match its checksum"
    return None


def find_resumable(folder: Path | str) -> tuple[Unit | None, list[tuple[Unit, str]]]:
    """The newest verified unit (or ``None``) and, newest first, the damaged units above it with reasons."""
    damaged: list[tuple[Unit, str]] = []
    for unit in reversed(list_units(folder)):
        problem = verify(unit)
        if problem is None:
            return unit, damaged
        damaged.append((unit, problem))
    return None, damaged


def legacy_unit(folder: Path | str) -> Unit | None:
    """The single checkpoint of the layout before units (``latest.zip`` + ``state.json``), if present."""
    folder = Path(folder)
    if not (folder / LEGACY_MODEL).is_file() or not (folder / STATE).is_file():
        return None
    try:
        step = int(json.loads((folder / STATE).read_text())["num_timesteps"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return Unit(folder, step, legacy=True)


def remove_legacy_files(folder: Path | str) -> None:
    """Delete the pre-unit checkpoint files (once a unit supersedes them)."""
    for name in LEGACY_FILES:
        path = Path(folder) / name
        if path.is_file():
            path.unlink()


def write_unit(folder: Path | str, step: int, files: Mapping[str, Writer], state: dict) -> Unit:
    """Write, seal and publish the unit for ``step``; an existing unit of the same step is replaced.

    ``files`` maps each file name to the function that writes it; ``state`` goes into ``state.json``
    (with ``num_timesteps`` = ``step`` and the wall-clock ``time``).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = unit_name(step)
    staging = folder / f"{TMP_PREFIX}{name}"
    _remove_tree(staging)
    staging.mkdir()
    try:
        for file_name, write in files.items():
            write(staging / file_name)
            if not (staging / file_name).is_file():
                raise RuntimeError(f"checkpoint writer for {file_name} wrote nothing")
        payload = {**state, "num_timesteps": int(step), "time": time.time()}
        (staging / STATE).write_text(json.dumps(payload, indent=1) + "\n")
        seal(staging, step)
        publish(staging, folder / name)
    except BaseException:
        _remove_tree(staging)
        raise
    return Unit(folder / name, int(step))


def seal(staging: Path, step: int) -> None:
    """fsync every file of a staged unit and write its manifest (last, so a torn unit has none)."""
    entries = {}
    for path in sorted(staging.iterdir()):
        if path.name == MANIFEST:
            continue
        with open(path, "rb") as handle:
            os.fsync(handle.fileno())
        entries[path.name] = {"bytes": path.stat().st_size, "sha256": _sha256(path)}
    manifest = staging / MANIFEST
    with open(manifest, "w") as handle:
        handle.write(json.dumps({"format": FORMAT, "step": int(step), "files": entries}, indent=1) + "\n")
        handle.flush()
        os.fsync(handle.fileno())
    fsync_directory(staging)


def publish(staging: Path, final: Path) -> None:
    """Move a sealed unit into place with one rename and make the rename durable."""
    if final.exists():
        # Same step saved twice (a resumed run's final save): move the old one aside first, since a
        # rename cannot replace a non-empty directory. Meanwhile the older units remain as fallbacks.
        aside = final.with_name(f"{TMP_PREFIX}replaced-{final.name}")
        _remove_tree(aside)
        os.rename(final, aside)
        os.rename(staging, final)
        _remove_tree(aside)
    else:
        os.rename(staging, final)
    fsync_directory(final.parent)


def prune(folder: Path | str, keep: int) -> list[Path]:
    """Delete all but the newest ``keep`` units; returns the deleted directories."""
    units = list_units(folder)
    doomed = units[:-keep] if keep > 0 else units
    for unit in doomed:
        discard(unit)
    return [unit.path for unit in doomed]


def discard(unit: Unit) -> None:
    """Delete a unit: renamed to a temporary name first, so a kill mid-delete leaves no half unit."""
    aside = unit.path.with_name(f"{TMP_PREFIX}discarded-{unit.path.name}")
    _remove_tree(aside)
    os.rename(unit.path, aside)
    fsync_directory(unit.path.parent)
    _remove_tree(aside)


def clean_temporary(folder: Path | str) -> list[Path]:
    """Remove staging directories and temporary files left in ``folder`` by a killed writer."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    stale = [p for p in folder.iterdir() if p.name.startswith(TMP_PREFIX)] + temporary_files(folder)
    for path in stale:
        _remove_tree(path)
    return stale


def model_files(model: BaseAlgorithm) -> dict[str, Writer]:
    """Writers for what SB3 itself needs to continue: the model, a replay buffer, reward normaliser."""
    files: dict[str, Writer] = {MODEL: model.save}
    if isinstance(model, OffPolicyAlgorithm) and model.replay_buffer is not None:
        files[REPLAY_BUFFER] = model.save_replay_buffer
    normalizer = model.get_vec_normalize_env()
    if normalizer is not None:
        files[NORMALIZER] = lambda path: normalizer.save(str(path))
    return files


def load_model(unit: Unit, cls: type[BaseAlgorithm], env: GymEnv | None, **kwargs: Any) -> BaseAlgorithm:
    """``cls.load`` the unit's model onto ``env`` (already wrapped in the unit's normaliser) with its replay buffer."""
    path = unit.file(MODEL)
    if path is None:
        raise FileNotFoundError(f"checkpoint unit {unit.path} has no {MODEL}")
    model = cls.load(path, env=env, **kwargs)
    replay = unit.file(REPLAY_BUFFER)
    if isinstance(model, OffPolicyAlgorithm) and replay is not None:
        model.load_replay_buffer(replay)
    return model


class CheckpointCallback(BaseCallback):
    """Write a unit every ``freq_steps`` environment steps or ``minutes`` of wall time, whichever comes first.

    Units are taken at rollout starts only: there every collected step has been trained on (PPO trains
    after ``_on_rollout_end``; off-policy learners have stored the transitions and done their gradient
    steps), so a unit's ``num_timesteps`` is exactly what the model has learnt from.

    Args:
        folder: the run's ``checkpoints`` directory.
        freq_steps: environment steps (summed over the vector env) between units.
        minutes: wall-clock minutes between units (``inf``: steps only).
        keep: units kept (the newest).
        state: returns extra ``state.json`` entries at save time.
        files: returns extra ``{name: writer}`` at save time.
        clock: seconds, monotonic (for tests).
    """

    def __init__(self, folder: Path | str, freq_steps: int, minutes: float, keep: int,
                 state: Callable[[], dict] | None = None, files: Callable[[], dict[str, Writer]] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.folder = Path(folder)
        self.freq_steps, self.seconds, self.keep = int(freq_steps), float(minutes) * 60.0, int(keep)
        self.extra_state, self.extra_files, self.clock = state, files, clock
        self.last_step, self.last_time = 0, clock()
        self.saved: list[int] = []

    def _on_training_start(self) -> None:
        self.last_step, self.last_time = self.model.num_timesteps, self.clock()

    def _on_rollout_start(self) -> None:
        step = self.model.num_timesteps
        if step > self.last_step and (step - self.last_step >= self.freq_steps
                                      or self.clock() - self.last_time >= self.seconds):
            self.save()

    def _on_step(self) -> bool:
        return True

    def save(self) -> Unit:
        """Write a unit of the model as it is now (call only where it has trained on every step)."""
        files = model_files(self.model)
        files.update(self.extra_files() if self.extra_files else {})
        unit = write_unit(self.folder, self.model.num_timesteps, files,
                          self.extra_state() if self.extra_state else {})
        prune(self.folder, self.keep)
        self.last_step, self.last_time = unit.step, self.clock()
        self.saved.append(unit.step)
        return unit


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _remove_tree(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()

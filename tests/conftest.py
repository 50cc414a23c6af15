"""Shared test fixtures: the independent reference values and finite-difference helpers."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

#: Values of an independent implementation of both papers (a copy kept in the repository).
REFERENCE_PATH = Path(__file__).resolve().parent / "data" / "reference_values.json"


def load_reference() -> dict:
    """The reference values; a missing file is an error (never a skipped test)."""
    if not REFERENCE_PATH.exists():
        raise FileNotFoundError(f"reference values missing: {REFERENCE_PATH} (part of the repository)")
    return json.loads(REFERENCE_PATH.read_text())


@pytest.fixture(autouse=True)
def plugin_modules_stay_in_their_test():
    """A registration records its module in CONTINUUM_GYM_PLUGINS for child processes (continuum_gym.plugins);
    a test's registrations must not make later tests' subprocesses import that test's module."""
    from continuum_gym.plugins import ENV_VAR

    before = os.environ.get(ENV_VAR)
    yield
    if before is None:
        os.environ.pop(ENV_VAR, None)
    else:
        os.environ[ENV_VAR] = before


@pytest.fixture(scope="session")
def reference() -> dict:
    return load_reference()


def fd_twist_jacobian(fk, q, h=1e-6):
    """Central-difference 6 x n Jacobian of a pose map fk(q) -> (p, R): [dp; log(R+ R-^T)/2h]."""
    q = np.asarray(q, dtype=float)
    J = np.empty((6, q.size))
    for k in range(q.size):
        dq = np.zeros_like(q)
        dq[k] = h
        p_plus, R_plus = fk(q + dq)
        p_minus, R_minus = fk(q - dq)
        J[:3, k] = (p_plus - p_minus) / (2 * h)
        J[3:, k] = Rotation.from_matrix(R_plus @ R_minus.T).as_rotvec() / (2 * h)
    return J


def fd_gradient(f, x, h=1e-6):
    """Central-difference gradient (or Jacobian, rows = outputs) of f at x."""
    x = np.asarray(x, dtype=float)
    columns = []
    for k in range(x.size):
        dx = np.zeros_like(x)
        dx[k] = h
        columns.append((np.asarray(f(x + dx)) - np.asarray(f(x - dx))) / (2 * h))
    return np.stack(columns, axis=-1)

"""Shared test fixtures: the independent reference values and finite-difference helpers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

REFERENCE_CANDIDATES = [
    Path(__file__).resolve().parents[1] / "tests" / "data" / "reference_values.json",
    Path(__file__).resolve().parents[2] / "shared" / "reference" / "reference_values.json",
]


def load_reference() -> dict:
    for path in REFERENCE_CANDIDATES:
        if path.exists():
            return json.loads(path.read_text())
    raise FileNotFoundError("reference_values.json not found in " + ", ".join(map(str, REFERENCE_CANDIDATES)))


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

"""The library's core is written once: an env declares its rows (``RowFunctions``) and the library binds a core.

A declaration that the library could not run (no ``NON_FINITE`` last flag, a state field it cannot allocate) is
refused when it is made, naming what is wrong, not deep inside a later step; the shipped envs' cores are bindings
of ``BatchedCore`` with no code of their own.
"""

from collections import namedtuple

import numpy as np
import pytest

from continuum_gym.envs.batched import BatchedCore
from continuum_gym.envs.columns import NON_FINITE, Columns
from continuum_gym.envs.core import Extra, RowFunctions
from continuum_gym.envs.occlusion import OcclusionCore
from continuum_gym.envs.occlusion.env import ROWS as OCCLUSION_ROWS
from continuum_gym.envs.view_tracking import ViewTrackingCore


@pytest.mark.parametrize("core", [OcclusionCore, ViewTrackingCore])
def test_the_shipped_cores_are_bindings_without_code_of_their_own(core):
    assert core.__bases__ == (BatchedCore,)
    assert set(vars(core)) <= {"spec", "rows", "__module__", "__doc__", "__qualname__"}
    assert core.rows.flags.names()[-1] == "NON_FINITE"


def test_the_library_allocates_every_array_a_declaration_names():
    core = OcclusionCore(num_envs=3)
    assert core.q.shape == (3, 7) and core.gamma.shape == (3,) and core.base_info.shape == (3, 2)
    assert core.base_info.dtype == np.int64 and core.metrics.shape == (3, len(OCCLUSION_ROWS.metrics))
    for bundle in (core._state, core._out):
        for name, array in zip(bundle._fields, bundle):
            assert array is (core._faults if name == "faults" else getattr(core, name)), name
    assert core.joint_values().shape == (3, 8) and core.circular_joint_columns == (7,)


def _declaration(flags, state):
    kwargs = {name: getattr(OCCLUSION_ROWS, name) for name in (
        "make_work", "observe_row", "step_row", "outputs", "metrics", "observation", "reward_terms", "build",
        "controller_observation", "controller", "arrays")}
    return RowFunctions(params=namedtuple("ToyParams", ["x"]), flags=flags, state=state, **kwargs)


def test_a_declaration_the_library_cannot_run_is_refused_when_made():
    class NoNonFinite(Columns):
        TERMINATED = "ended"
        TRUNCATED = "over"

    class Flags(Columns):
        TERMINATED = "ended"
        TRUNCATED = "over"
        NON_FINITE = NON_FINITE

    with pytest.raises(ValueError, match="last flag must be NON_FINITE"):
        _declaration(NoNonFinite, OCCLUSION_ROWS.state)
    with pytest.raises(ValueError, match="field 'speed' is neither one of the library's arrays"):
        _declaration(Flags, namedtuple("ToyState", ["q", "steps", "speed"]))
    _declaration(Flags, namedtuple("ToyState", ["q", "steps"]))  # these it can allocate
    assert Extra().shape == () and Extra(joint=True).joint


def test_batched_core_itself_is_not_an_environment():
    with pytest.raises(TypeError, match="bound to an environment by envs.front_ends"):
        BatchedCore(num_envs=1)

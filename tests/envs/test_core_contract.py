"""The batched core's contract: declared once in ``BatchedCore``, enforced at the class statement."""

import abc

import pytest

from continuum_gym.envs.batched import BatchedCore
from continuum_gym.envs.occlusion import OcclusionCore
from continuum_gym.envs.view_tracking import ViewTrackingCore


def test_every_hook_the_front_ends_call_is_declared_abstract_with_a_docstring():
    hooks = {name for name, value in vars(BatchedCore).items() if getattr(value, "__isabstractmethod__", False)}
    assert hooks == {"reset_rows", "step_values", "controller_observation", "kernel_model"}
    for name in hooks | {"make_scene", "render_row", "pixel_occlusion", "step", "observe_rows", "joint_values"}:
        assert getattr(BatchedCore, name).__doc__, name
    assert isinstance(BatchedCore, abc.ABCMeta)


@pytest.mark.parametrize("core", [OcclusionCore, ViewTrackingCore])
def test_the_shipped_cores_fulfil_it(core):
    assert not core.__abstractmethods__
    for name in BatchedCore.REQUIRED_CLASS_ATTRIBUTES:
        assert getattr(core, name) is not None, name


def test_a_core_that_lacks_a_hook_or_an_attribute_fails_at_its_class_statement():
    with pytest.raises(TypeError, match=r"Partial is a BatchedCore but does not define .*controller_observation"
                                        r".*step_values.*spec"):
        class Partial(OcclusionCore.__mro__[1]):  # BatchedCore itself
            def reset_rows(self, rows, task_ids):
                pass

            def kernel_model(self):
                return ()

    with pytest.raises(TypeError, match=r"does not define step_kernel$|does not define step_kernel "):
        class NoKernel(OcclusionCore):
            step_kernel = None

    class Base(BatchedCore, abstract=True):  # a partial core, declared as such, is allowed
        spec = OcclusionCore.spec

    class Complete(Base, OcclusionCore):  # ... and completed by another
        pass

    assert Complete.spec is OcclusionCore.spec and not Complete.__abstractmethods__

"""``get_spec``: what an unknown id is told, since every command and front end asks it first."""

from __future__ import annotations

import gymnasium as gym
import pytest

from continuum_gym.envs.spec import get_spec
from continuum_gym.plugins import ENTRY_POINT_GROUP, ENV_VAR

#: What a user must read to make their own id known: where ids come from and the three ways to import it.
HOW_TO_REGISTER = ("registered at import of", "--import MODULE", ENTRY_POINT_GROUP, f"{ENV_VAR}=MODULE")


def test_an_unknown_id_says_where_ids_come_from_and_how_to_import_a_users_module():
    with pytest.raises(ValueError) as raised:
        get_spec("MyLab/Occlusion4Seg-v0")
    message = str(raised.value)
    assert "unknown env id 'MyLab/Occlusion4Seg-v0'" in message and "ContinuumGym/OcclusionAvoidance-v0" in message
    for needle in HOW_TO_REGISTER:
        assert needle in message, needle


def test_an_id_registered_to_another_entry_point_is_named_as_such():
    gym.register(id="MyTest/NotOurs-v0", entry_point="gymnasium.envs.classic_control.cartpole:CartPoleEnv")
    try:
        with pytest.raises(ValueError, match="registered to 'gymnasium.envs.classic_control.cartpole:CartPoleEnv'"):
            get_spec("MyTest/NotOurs-v0")
    finally:
        gym.registry.pop("MyTest/NotOurs-v0")

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest

from sim import get_world


@pytest.fixture(scope="session")
def nav():
    return get_world("nav2d")


@pytest.fixture(scope="session")
def nav_policy(nav):
    from policy import base_policy

    return base_policy(nav)

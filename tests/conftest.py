import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="session")
def field():
    from robotatfactory.field import load_field

    return load_field()


@pytest.fixture(scope="session")
def robot():
    from robotatfactory.robot import load_robot

    return load_robot()


@pytest.fixture
def raf_cmd():
    """The raf command line as a list, run with this interpreter."""
    return [sys.executable, "-m", "robotatfactory"]

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("MUJOCO_GL", "egl")
if "RAF_CACHE_DIR" not in os.environ:  # the agent's leg-time table: one per test session, not the user's cache
    import atexit
    import shutil
    import tempfile

    os.environ["RAF_CACHE_DIR"] = tempfile.mkdtemp(prefix="raf-test-cache-")
    atexit.register(shutil.rmtree, os.environ["RAF_CACHE_DIR"], True)


@pytest.fixture(scope="session")
def field():
    from robotatfactory.field import load_field

    return load_field()


@pytest.fixture(scope="session")
def robot():
    from robotatfactory.robot import load_robot

    return load_robot()


@pytest.fixture(scope="session")
def scene_camera_robot():
    """The robot with the camera SimTwo's scene states (AGV.xml: 30 deg down, 0.1165 m up), not the one SimTwo was
    measured to render (the robot file's 29.64 deg, 0.1169 m since 2026-11-30): what tests made or posed with the
    scene's numbers before that keep."""
    from dataclasses import replace

    from robotatfactory.robot import load_robot

    r = load_robot()  # (not the robot fixture: a test module may override that one)
    return replace(r, camera=replace(r.camera, pitch_down_deg=30.0, xyz=(0.05, 0.0, 0.1165)))


@pytest.fixture
def raf_cmd():
    """The raf command line as a list, run with this interpreter."""
    return [sys.executable, "-m", "robotatfactory"]


def _middlewares() -> list[str]:
    """The middlewares a ``middleware``-taking test runs on in this interpreter: the one it has (``.venv``:
    ros1, ``.venv-ros2``: ros2); RAF_MIDDLEWARE, when set, names it. One a process: rospy and rclpy never
    share an interpreter, and the test node is made once."""
    from robotatfactory.ros import mw

    want = os.environ.get("RAF_MIDDLEWARE", "").strip().lower()
    have = mw.available()
    return [want] if want in have else have[:1]


def pytest_generate_tests(metafunc):
    """Parametrise the ``middleware`` fixture with this interpreter's middleware: ids read ``[ros1]`` /
    ``[ros2]``. A middleware the interpreter lacks is not a parameter (nothing is skipped); the README's test
    command runs the ``middlewares``-marked tests in both environments (scripts/bootstrap.sh test)."""
    if "middleware" in metafunc.fixturenames:
        metafunc.parametrize("middleware", _middlewares(), scope="session")


@pytest.fixture(autouse=True)
def _callbacks_of_the_test_node_did_not_raise():
    """A callback that raises on rosutil's ROS 2 test node (a node under test run in this process, e.g. the
    agent's) fails the test it happened in (rosutil's spin thread catches it so that later tests still hear)."""
    ru = sys.modules.get("rosutil")
    n0 = len(ru.SPIN_ERRORS) if ru is not None else 0
    yield
    ru = sys.modules.get("rosutil")
    if ru is not None and len(ru.SPIN_ERRORS) > n0:
        new = ru.SPIN_ERRORS[n0:]
        pytest.fail(f"{len(new)} callback error(s) on the test node; the first:\n{new[0]}", pytrace=False)

"""Generates the Python classes of the package's services (src/robotatfactory/srv/) from srv/*.srv with genpy.

There is no catkin build here: scripts/bootstrap.sh runs this script whenever a .srv file is newer than the
generated package (which git ignores, as generated output), and tests/test_sim_services.py checks that the
package is what this script makes of the .srv files now. In a catkin workspace, or after editing a .srv file
by hand, run it yourself:

    python3 srv/generate.py

rosservice finds them as the ROS package ``robotatfactory``'s services (``import robotatfactory.srv``):
the package is catkin-style, so roslib adds nothing to sys.path and the Python package must be importable
(``.venv/bin/python``, or ``PYTHONPATH=src`` for /usr/bin/rosservice).
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "src" / "robotatfactory" / "srv"


def generate(out: Path = OUT) -> list[Path]:
    sys.path.append("/usr/lib/python3/dist-packages")  # genpy/genmsg from Debian's ROS (also in the venv)
    import genpy.generator
    import genpy.generate_initpy

    out.mkdir(parents=True, exist_ok=True)
    files = sorted(str(p) for p in HERE.glob("*.srv"))
    rc = genpy.generator.SrvGenerator().generate_messages("robotatfactory", files, str(out), {})
    if rc:
        raise SystemExit(f"genpy failed ({rc})")
    genpy.generate_initpy.write_modules(str(out))
    return sorted(out.glob("*.py"))


if __name__ == "__main__":
    for p in generate():
        print(p)

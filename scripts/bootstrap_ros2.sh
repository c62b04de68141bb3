#!/usr/bin/env bash
# Idempotent setup of the ROS 2 Jazzy environment .venv-ros2 (Debian 12, no ROS 2 apt repository):
#  - installs the Debian packages the interface builds need (cmake g++ ninja-build python3-dev)
#  - creates .venv-ros2 WITHOUT system site-packages (Debian's ROS 1 Python defines std_msgs etc. too)
#  - installs the pinned requirements-ros2.txt (ros-jazzy-* wheels from PyPI, rosbags, the core deps)
#    and the package itself (editable)
#  - points the wheels' exported CMake files at this machine's Python and numpy headers
#  - builds ros2/tf2_msgs, ros2/robotatfactory_msgs (its .srv files are the repository's srv/*.srv) and
#    ros2/simulation_interfaces (the standard's interface files as Jazzy releases them: ros2/simulation_interfaces/UPSTREAM)
#    with cmake + ninja under build/ros2/ and installs them into the venv's own prefix, where rclpy
#    finds them with no environment variables (as it finds the wheels)
#  - runs scripts/check_ros2.py once after anything was (re)built
# Each step is keyed on a hash of its inputs (stamp files in .venv-ros2/): a second run with nothing
# changed does no network access and takes well under a second. scripts/bootstrap.sh calls this.
#
# usage: scripts/bootstrap_ros2.sh   (environment: CI=true is fine without a terminal; RAF_ROS2_VENV to
#        put the venv elsewhere)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV=${RAF_ROS2_VENV:-$ROOT/.venv-ros2}
PY=$VENV/bin/python
BUILD=$ROOT/build/ros2
INTERFACE_PACKAGES=(tf2_msgs robotatfactory_msgs simulation_interfaces)
export PIP_NO_INPUT=1 PIP_DISABLE_PIP_VERSION_CHECK=1 DEBIAN_FRONTEND=noninteractive

# one run at a time (several shells may run scripts/bootstrap.sh at once): the others wait, then find
# everything stamped and do nothing
mkdir -p "$ROOT/build"
exec 9> "$ROOT/build/.bootstrap-ros2.lock"
if ! flock -n 9; then
  echo "[bootstrap-ros2] another bootstrap_ros2.sh is running: waiting for it"
  flock 9
fi

log() { echo "[bootstrap-ros2] $*"; }
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f s", b - a }'; }
hash_of() { cat "$@" | sha256sum | cut -d' ' -f1; }
stamp_ok() { [ -f "$1" ] && [ "$(cat "$1")" = "$2" ]; }
pip_install() {  # quiet; drops only the warnings about pip.conf index folders that do not exist here
  "$PY" -m pip install -q "$@" 2> >(grep -v "^WARNING: Location '.*' is ignored: it is neither a file nor a directory" >&2)
}

# --- Debian packages ------------------------------------------------------------------------------
DEB_PACKAGES=(cmake g++ ninja-build python3-dev python3-venv)
. scripts/debs.sh
install_debs bootstrap-ros2 "${DEB_PACKAGES[@]}"

# --- the venv (no system site-packages) ------------------------------------------------------------
if [ -f "$VENV/pyvenv.cfg" ] && grep -qi '^include-system-site-packages *= *true' "$VENV/pyvenv.cfg"; then
  log "$VENV sees the system site-packages (Debian's ROS 1): making it again"
  rm -rf "$VENV"
fi
if [ ! -x "$PY" ]; then
  t=$(now)
  log "creating $VENV (no system site-packages)"
  /usr/bin/python3 -m venv "$VENV"
  log "venv created ($(since "$t"))"
fi

# --- pip: the wheels when requirements-ros2.txt changed, the package when pyproject.toml changed ----------
pip_stamp=$VENV/.raf-ros2-pip
pip_want=$(hash_of requirements-ros2.txt)
if ! stamp_ok "$pip_stamp" "$pip_want"; then
  t=$(now)
  log "installing requirements-ros2.txt (ros-jazzy-* wheels, rosbags, the core deps)"
  # setuptools and wheel first, so that sdists (empy) build as wheels, not by the legacy setup.py path
  # shellcheck disable=SC2046
  pip_install $(grep -E '^(setuptools|wheel)==' requirements-ros2.txt)
  pip_install -r requirements-ros2.txt
  rm -f "$VENV/.raf-ros2-package"
  rm -rf "$BUILD"  # the interface packages are built again, from scratch, against the new wheels
  echo "$pip_want" > "$pip_stamp"
  log "requirements installed ($(since "$t"))"
fi
pkg_stamp=$VENV/.raf-ros2-package
pkg_want=$(hash_of pyproject.toml)
if ! stamp_ok "$pkg_stamp" "$pkg_want"; then
  t=$(now)
  log "installing robotatfactory (editable)"
  pip_install --no-deps --no-build-isolation -e .
  echo "$pkg_want" > "$pkg_stamp"
  log "robotatfactory installed ($(since "$t"))"
fi

# --- the wheels' CMake exports name the wheel builder's Python (/opt/python/cp311-cp311/...) -----------
# rosidl_generate_interfaces links the <pkg>__rosidl_generator_py targets, whose include directories are
# those; configure fails until they are this machine's. Cheap (a grep), so checked on every run: a pip
# reinstall of a wheel brings the wrong paths back.
broken=$(grep -l '/opt/python/' "$VENV"/share/*/cmake/*__rosidl_generator_pyExport.cmake 2>/dev/null || true)
if [ -n "$broken" ]; then
  read -r pyinc npinc < <("$PY" -c 'import sysconfig, numpy; print(sysconfig.get_paths()["include"], numpy.get_include())')
  # idempotent: the patterns match only the wheel builder's paths, which are gone after one pass
  # shellcheck disable=SC2086
  sed -i -E "s#/opt/python/[^/;\"]*/include/python3\.[0-9]+#$pyinc#g; s#/opt/python/[^;\"]*/site-packages/numpy/_core/include#$npinc#g" $broken
  log "pointed $(echo "$broken" | wc -l) CMake exports at $pyinc and numpy's headers"
fi

# --- the interface packages, built into the venv's prefix ----------------------------------------------
sources_of() {  # the files a package is built from
  find "ros2/$1" -type f | LC_ALL=C sort
  if [ "$1" = robotatfactory_msgs ]; then find srv -maxdepth 1 -name '*.srv' | LC_ALL=C sort; fi
}
pkg_hash() {  # the file names and contents, and the pip stamp (a new wheel set means a rebuild)
  { echo "$pip_want"; sources_of "$1"; sources_of "$1" | xargs -d '\n' cat; } | sha256sum | cut -d' ' -f1
}
built_any=0
for pkg in "${INTERFACE_PACKAGES[@]}"; do
  stamp=$VENV/.raf-ros2-$pkg
  want=$(pkg_hash "$pkg")
  if stamp_ok "$stamp" "$want"; then continue; fi
  t=$(now)
  log "building $pkg (ros2/$pkg -> $VENV)"
  dir=$BUILD/$pkg
  mkdir -p "$dir"
  if [ -f "$dir/install_manifest.txt" ]; then  # take the last build's files away (a .srv may be gone)
    xargs -d '\n' rm -f < "$dir/install_manifest.txt"
  fi
  run() {  # run a build step, its output in a log, shown when it fails
    local name=$1; shift
    if ! "$@" > "$dir/$name.log" 2>&1; then
      tail -n 40 "$dir/$name.log" >&2
      log "FAILED: $pkg $name (full log: $dir/$name.log)" >&2
      exit 1
    fi
  }
  t1=$(now)
  run configure cmake -G Ninja -S "$ROOT/ros2/$pkg" -B "$dir" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_INSTALL_PREFIX="$VENV" -DCMAKE_PREFIX_PATH="$VENV" -DPython3_EXECUTABLE="$PY" \
    -DBUILD_TESTING=OFF
  c=$(since "$t1"); t1=$(now)
  run build ninja -C "$dir"
  b=$(since "$t1"); t1=$(now)
  run install ninja -C "$dir" install
  echo "$want" > "$stamp"
  built_any=1
  log "$pkg built (configure $c, build $b, install $(since "$t1"); total $(since "$t"))"
done

# --- the smoke check, once after anything changed ----------------------------------------------------
check_stamp=$VENV/.raf-ros2-checked
check_want=$(cat "$pip_stamp" "$pkg_stamp" "${INTERFACE_PACKAGES[@]/#/$VENV/.raf-ros2-}" scripts/check_ros2.py | sha256sum | cut -d' ' -f1)
if [ "$built_any" = 1 ] || ! stamp_ok "$check_stamp" "$check_want"; then
  t=$(now)
  log "checking the environment (scripts/check_ros2.py)"
  if ! "$PY" scripts/check_ros2.py; then
    rm -f "$check_stamp"
    log "FAILED: scripts/check_ros2.py (see above)" >&2
    exit 1
  fi
  echo "$check_want" > "$check_stamp"
  log "check passed ($(since "$t"))"
fi
log "ready: $VENV/bin/python (ROS 2 Jazzy, rmw_fastrtps_cpp)"

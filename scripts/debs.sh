# Sourced by scripts/bootstrap.sh and scripts/bootstrap_ros2.sh: install_debs TAG PACKAGE... installs the
# Debian packages that are not installed yet (one apt-get run; nothing, and no network, when all are there).
install_debs() {
  local tag=$1 p sudo=""
  shift
  local missing=()
  for p in "$@"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
      missing+=("$p")
    fi
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
  echo "[$tag] installing Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

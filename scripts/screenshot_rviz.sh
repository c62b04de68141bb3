#!/usr/bin/env bash
# RViz screenshot for the README (docs/images/rviz.png): a private roscore on a free port, the stand-in
# simulator (lockstep, real time), the bridge (map -> odom from the first ground truth, since no localization
# runs here), RViz with rviz/robotatfactory.rviz under Xvfb while the robot drives an arc, dumped with xwd and
# converted to PNG with OpenCV. Usage: scripts/screenshot_rviz.sh [OUT.png] [SECONDS_FOR_RVIZ_TO_START]
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
OUT=${1:-docs/images/rviz.png}
WAIT=${2:-15}
PY=${RAF_PYTHON:-$ROOT/.venv/bin/python}
for t in roscore rviz Xvfb xwd; do command -v "$t" >/dev/null || { echo "screenshot_rviz: $t is not installed" >&2; exit 2; }; done

TMP=$(mktemp -d /tmp/raf-rviz-XXXXXX)
free_port() { "$PY" -c 'import socket,sys; s=socket.socket(socket.AF_INET, socket.SOCK_DGRAM if sys.argv[1]=="udp" else socket.SOCK_STREAM); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])' "$1"; }
MPORT=$(free_port tcp); BPORT=$(free_port udp); SPORT=$(free_port udp); CPORT=$(free_port tcp)
export ROS_MASTER_URI=http://127.0.0.1:$MPORT/ ROS_HOME=$TMP ROS_LOG_DIR=$TMP/log ROS_IP=127.0.0.1
export ROS_PACKAGE_PATH=$ROOT${ROS_PACKAGE_PATH:+:$ROS_PACKAGE_PATH}
DISP=91; while [ -e /tmp/.X$DISP-lock ] || [ -e /tmp/.X11-unix/X$DISP ]; do DISP=$((DISP + 1)); done

PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill -INT -- "-$p" 2>/dev/null || true; done
  sleep 1
  for p in "${PIDS[@]}"; do kill -KILL -- "-$p" 2>/dev/null || true; done
  rm -rf "$TMP"
}
trap cleanup EXIT
start() { setsid "$@" >"$TMP/$(basename "$1")-$#.log" 2>&1 & PIDS+=($!); disown; }

start roscore -p "$MPORT"
sleep 3
start "$PY" -m robotatfactory bridge --port "$BPORT" --camera "tcp://127.0.0.1:$CPORT" --set tf/map_to_odom=first_ground_truth
sleep 3
start "$PY" -m robotatfactory sim --port "$SPORT" --bridge "127.0.0.1:$BPORT" --camera-bind "tcp://127.0.0.1:$CPORT" \
  --no-server --lockstep --realtime --quiet --start-pose=-0.62,-0.42,0.9
sleep 4
start Xvfb ":$DISP" -screen 0 1600x960x24 -nolisten tcp
sleep 2
DISPLAY=":$DISP" LIBGL_ALWAYS_SOFTWARE=1 start rviz -d "$ROOT/rviz/robotatfactory.rviz"
sleep "$WAIT"
# drive a gentle arc while RViz watches, so that odometry and ground truth draw their paths, then stop
"$PY" - <<'PYEOF'
import time, rospy
from geometry_msgs.msg import Twist
rospy.init_node("raf_screenshot_driver", anonymous=True, disable_signals=True)
pub = rospy.Publisher("/cmd_vel", Twist, queue_size=1)
time.sleep(1.5)
tw = Twist(); tw.linear.x = 0.15; tw.angular.z = 0.3
end = time.time() + 5.0
while time.time() < end:
    pub.publish(tw); time.sleep(0.05)
pub.publish(Twist())
time.sleep(3.0)
PYEOF
xwd -root -silent -display ":$DISP" -out "$TMP/shot.xwd"
mkdir -p "$(dirname "$OUT")"
"$PY" - "$TMP/shot.xwd" "$OUT" <<'PYEOF'
import sys
import cv2
import numpy as np
b = open(sys.argv[1], "rb").read()
h = np.frombuffer(b[:100], dtype=">u4")
header, fmt, width, height, byte_order, bpp, bpl, ncolors = (int(h[i]) for i in (0, 2, 4, 5, 7, 11, 12, 19))
if fmt != 2 or bpp not in (24, 32):
    sys.exit(f"unsupported xwd: format {fmt}, {bpp} bits per pixel")
off = header + ncolors * 12
px = np.frombuffer(b[off:off + bpl * height], np.uint8).reshape(height, bpl)[:, :width * bpp // 8]
px = px.reshape(height, width, bpp // 8)
bgr = px[:, :, :3] if byte_order == 0 else (px[:, :, 1:4][:, :, ::-1] if bpp == 32 else px[:, :, ::-1])
cv2.imwrite(sys.argv[2], np.ascontiguousarray(bgr))
print(f"wrote {sys.argv[2]} ({width}x{height})")
PYEOF

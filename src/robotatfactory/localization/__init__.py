"""Localization of the robot on the field, plain Python (no ROS import anywhere in this package).

Modules (each one job; import what you need, this package imports nothing on its own so that
``import robotatfactory.localization.odometry`` stays light):

- :mod:`.geometry`   SE(2)/SE(3) helpers, angle wrapping, the robot<->camera transforms.
- :mod:`.detect`     ArUco detection (OpenCV ``ArucoDetector``, 5x5 dictionary, sub-pixel corners).
- :mod:`.markerpose` per-marker IPPE poses (both solutions) and the camera-mount check.
- :mod:`.estimators` camera / robot pose from a frame: the paper's closest-marker method, one PnP over all
  markers, and the planar (x, y, heading) fit with the mount fixed; covariances; rejection reasons.
- :mod:`.ekf`        the EKF on (x, y, heading) in ``map``: odometry prediction, stamped (late) updates,
  Mahalanobis gating, re-initialisation.
- :mod:`.lidar`      LIDAR beacon extraction and the range/bearing measurement.
- :mod:`.pipeline`   one camera frame in, all estimates out (used by the ROS node, the bench, the experiment).
- :mod:`.synth`      synthetic camera images of the field (tests and the bench).
- :mod:`.odometry`   wheel odometry (owned by the bridge).
"""

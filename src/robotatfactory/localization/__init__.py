"""Localization of the robot on the field, plain Python (no ROS import anywhere in this package).

Modules (each one job; import what you need: this package imports nothing on its own, so that
``import robotatfactory.localization.odometry`` stays light). See docs/localization.md.

- :mod:`.detect`     ArUco detection (OpenCV ``ArucoDetector``, the field's 5x5 dictionary, sub-pixel corners).
- :mod:`.markerpose` per-marker IPPE poses (both solutions), the camera-mount check, the corner noise model.
- :mod:`.estimators` camera / robot pose from a frame: the paper's closest-marker method, one PnP over all
  markers, the planar (x, y, heading) fit with the mount fixed; consensus, covariances, sanity checks.
- :mod:`.pipeline`   one camera frame in, every estimate out, rejection counters (node, bench, experiment).
- :mod:`.ekf`        the EKF on (x, y, heading) in ``map``: odometry prediction, stamped (late) updates,
  Mahalanobis gating, re-initialisation, LIDAR beacon updates.
- :mod:`.lidar`      LIDAR beacon extraction (and a scan simulator for tests).
- :mod:`.reasons`    the names rejections are counted under.
- :mod:`.draw`       the debug image (markers, IDs, axes, estimates).
- :mod:`.config`     the settings: one typed object (``LocalizationConfig``), one validation
  (``config/localization.yaml`` is generated from it).
- :mod:`.geometry`   SE(2)/SE(3) helpers, angle wrapping.
- :mod:`.synth`, :mod:`.frames` synthetic camera images; random poses and test frames (synthetic or simulator).
- :mod:`.route`, :mod:`.metrics` the experiment's reference route and pure pursuit; error statistics.
- :mod:`.odometry`   wheel odometry from tick totals (owned by the bridge).
"""

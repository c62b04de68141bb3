"""Why an input was rejected. Every rejection is counted under one of these names (diagnostics show them)."""
from __future__ import annotations

# per marker
UNKNOWN_ID = "unknown_id"  # decoded ID not on the field map
DUPLICATE_ID = "duplicate_id"  # the same ID twice in one frame: one of them is not the field's marker
DEGENERATE = "degenerate"  # corners not finite, too small, not convex, too thin
TOO_FAR = "too_far"  # marker farther than max_marker_distance
PNP_FAILED = "pnp_failed"  # IPPE gave no solution
MOUNT_CHECK = "mount_check"  # no IPPE solution puts the camera at its height/tilt/roll on the robot
MARKER_OUTLIER = "marker_outlier"  # disagrees with the other markers of the frame
# per frame / estimate
NO_MARKERS = "no_markers"  # a frame without any usable marker
FAR_LONE_MARKER = "far_lone_marker"  # one marker only, and it is far: the ambiguity zone
REPROJECTION = "reprojection"  # the fit does not explain the corners
OUTSIDE_FIELD = "outside_field"
INSIDE_WALL = "inside_wall"
UNCERTAIN = "uncertain"  # covariance above the configured limit
NOT_FINITE = "not_finite"
# filter
GATED = "gated"  # Mahalanobis distance above the gate
TOO_OLD = "too_old"  # stamp older than the filter's history
NUMERICAL = "numerical"  # singular innovation covariance or a non-finite result
BAD_INPUT = "bad_input"  # non-finite or malformed input to the filter
REINITIALISED = "reinitialised"  # not a rejection: the filter was reset from a confident fix

ALL = (UNKNOWN_ID, DUPLICATE_ID, DEGENERATE, TOO_FAR, PNP_FAILED, MOUNT_CHECK, MARKER_OUTLIER, NO_MARKERS,
       FAR_LONE_MARKER, REPROJECTION, OUTSIDE_FIELD, INSIDE_WALL, UNCERTAIN, NOT_FINITE, GATED, TOO_OLD,
       NUMERICAL, BAD_INPUT, REINITIALISED)


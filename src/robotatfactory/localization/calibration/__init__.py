"""Camera calibration against the field (``raf calibrate``; docs/calibration.md), one job a module:

- :mod:`.model`       the camera's parameter vector, one frame's data, projecting world points into the image;
- :mod:`.solver`      the joint least-squares fit over many frames (:func:`calibrate`), its settings and result,
                      and odometry interpolated at the frames' stamps;
- :mod:`.fileformat`  calibration files (write, read and check once, apply to a camera) and robot files;
- :mod:`.synthetic`   a perturbed camera, exact synthetic detections and a fit's errors against the truth.

The names below are the package's public interface.
"""
from .fileformat import (Calibration, calibrated_robot, calibration_dict, camera_dict, load_calibration,
                         robot_dict, write_calibration, write_robot_json)
from .model import (DEFAULT_FREE, DISTORTION, PARAMS, UNITS, FrameData, camera_from_vector, camera_vector, distort,
                    predict_corners, project_corners)
from .solver import CalibrationConfig, CalibrationResult, calibrate, interpolate_odometry
from .synthetic import compare, perturbed_robot, synthetic_frames

__all__ = ["Calibration", "CalibrationConfig", "CalibrationResult", "DEFAULT_FREE", "DISTORTION", "FrameData",
           "PARAMS", "UNITS", "calibrate", "calibrated_robot", "calibration_dict", "camera_dict",
           "camera_from_vector", "camera_vector", "compare", "distort", "interpolate_odometry", "load_calibration",
           "perturbed_robot", "predict_corners", "project_corners", "robot_dict", "synthetic_frames",
           "write_calibration", "write_robot_json"]

"""The RobotAtFactory 4.0 competition map as data: markers, walls, slots, areas.

>>> from robotatfactory.field import load_field
>>> f = load_field()            # the 2026 rules; load_field("simtwo2022") for SimTwo's public scene
>>> f.marker(13).position
array([0., 0., 0.])
"""
from .loader import DEFAULT_FIELD, FieldError, available_fields, load_field, marker_pose
from .model import Area, Box, Field, Marker, PartSpec, Pose2D, Slot

__all__ = ["DEFAULT_FIELD", "FieldError", "available_fields", "load_field", "marker_pose",
           "Area", "Box", "Field", "Marker", "PartSpec", "Pose2D", "Slot"]

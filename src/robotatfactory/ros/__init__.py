"""ROS 1 wiring (rospy) for robotatfactory. Thin: the algorithms live in the plain-Python packages.

- :mod:`.config`        the bridge's parameters: defaults, validation (no rospy import)
- :mod:`.messages`      ROS messages from the pure objects (Odometry, LaserScan, Image, TF, ...)
- :mod:`.field_markers` the field as a visualization_msgs/MarkerArray and static marker TFs
- :mod:`.bridge_node`   the bridge node: SimTwo's UDP and ZMQ streams <-> ROS topics and TF

Nothing is imported here, so that ``robotatfactory.ros.config`` stays importable without ROS.
"""

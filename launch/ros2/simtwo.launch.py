"""The real SimTwo on Linux on ROS 2: raf simtwo run (headless, built by raf simtwo build), the bridge, the
localization node and, optionally, RViz 2. The ROS 1 twin is launch/simtwo.launch (the same arguments).

    ros2 launch robotatfactory simtwo.launch.py
    ros2 launch robotatfactory simtwo.launch.py round:=2 seed:=3 rviz:=true

SimTwo's scene is the field simtwo2022; round and seed put the round's parts on its incoming slots. Without
the localization node, map -> odom is taken once from SimTwo's first ground-truth pose. raf simtwo run is no
ROS node: it runs as a process (its `raf` launcher from this package); when it ends, the launch ends.
"""
import os
import shlex

from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, ExecuteProcess, GroupAction, IncludeLaunchDescription,
                            OpaqueFunction, Shutdown)
from launch.conditions import IfCondition, UnlessCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from robotatfactory.simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SIMTWO_UDP_PORT


def _raf_simtwo(context):
    """raf simtwo run's command line (simtwo_args is split as a shell would)."""
    from ament_index_python.packages import get_package_prefix

    def a(name):
        return LaunchConfiguration(name).perform(context)

    raf = os.path.join(get_package_prefix("robotatfactory"), "lib", "robotatfactory", "raf")
    cmd = [raf, "--field", a("field"), "simtwo", "run", "--port", a("sim_port"), "--bridge",
           f"{LOCALHOST}:{a('port')}", "--camera-port", a("camera_port"), "--round", a("round"), "--seed", a("seed"),
           *shlex.split(a("simtwo_args"))]
    return [ExecuteProcess(cmd=cmd, name="raf_simtwo", output="screen", on_exit=Shutdown(reason="SimTwo ended"),
                           additional_env={"RAF_MIDDLEWARE": "ros2"})]


def _bridge(share, arg, map_to_odom: str, condition):
    return GroupAction(scoped=True, condition=condition, actions=[  # the include's arguments stay in it
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(PathJoinSubstitution([share, "launch", "ros2", "bridge.launch.py"])),
            launch_arguments={
                "field": arg("field"),
                "map_to_odom": map_to_odom,
                "port": arg("port"),
                "camera": [f"tcp://{LOCALHOST}:", arg("camera_port")],
                "sim_control": "",
            }.items(),
        ),
    ])


def generate_launch_description():
    def arg(name):
        return LaunchConfiguration(name)

    share = FindPackageShare("robotatfactory")
    return LaunchDescription([
        DeclareLaunchArgument("field", default_value="simtwo2022", description="SimTwo's scene's map"),
        DeclareLaunchArgument("round", default_value="1", description="the round whose parts are placed"),
        DeclareLaunchArgument("seed", default_value="0", description="the round draw's seed"),
        DeclareLaunchArgument("simtwo_args", default_value="", description="more raf simtwo run options"),
        DeclareLaunchArgument("localize", default_value="true", description="run the localization node"),
        DeclareLaunchArgument("rviz", default_value="false", description="start RViz 2 (fixed frame map)"),
        DeclareLaunchArgument("port", default_value=str(BRIDGE_UDP_PORT), description="the bridge's UDP port"),
        DeclareLaunchArgument("sim_port", default_value=str(SIMTWO_UDP_PORT), description="SimTwo's UDP port"),
        DeclareLaunchArgument("camera_port", default_value=str(CAMERA_ZMQ_PORT),
                              description="SimTwo's camera port (ZMQ)"),
        OpaqueFunction(function=_raf_simtwo),
        _bridge(share, arg, "none", IfCondition(arg("localize"))),
        _bridge(share, arg, "first_ground_truth", UnlessCondition(arg("localize"))),
        GroupAction(scoped=True, condition=IfCondition(arg("localize")), actions=[
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(PathJoinSubstitution([share, "launch", "ros2",
                                                                    "localization.launch.py"])),
                launch_arguments={"field": arg("field")}.items(),
            ),
        ]),
        Node(package="rviz2", executable="rviz2", name="rviz2", arguments=["-f", "map"], output="screen",
             condition=IfCondition(arg("rviz"))),
    ])

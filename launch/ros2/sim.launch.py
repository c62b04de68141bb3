"""Everything on one machine on ROS 2: the stand-in simulator (raf sim, lockstep), the bridge and, optionally,
RViz 2. The ROS 1 twin is launch/sim.launch (the same arguments).

    ros2 launch robotatfactory sim.launch.py
    ros2 launch robotatfactory sim.launch.py rviz:=true sim_args:="--lockstep --beacons"

Without a localization node, map -> odom is taken once from the simulator's first ground-truth pose
(map_to_odom:=first_ground_truth) so that RViz can show the robot on the field. raf sim is no ROS node: it
runs as a process (its `raf` launcher from this package); when it ends, the launch ends.
"""
import os
import shlex

from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, ExecuteProcess, GroupAction, IncludeLaunchDescription,
                            OpaqueFunction, Shutdown)
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from robotatfactory.sim.control import CONTROL_PORT_OFFSET
from robotatfactory.simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SERVER_UDP_PORT, SIMTWO_UDP_PORT


def _raf_sim(context):
    """raf sim's command line (sim_args is split as a shell would)."""
    from ament_index_python.packages import get_package_prefix

    def a(name):
        return LaunchConfiguration(name).perform(context)

    raf = os.path.join(get_package_prefix("robotatfactory"), "lib", "robotatfactory", "raf")
    cmd = [raf, "--field", a("field"), "sim", "--bridge", f"{LOCALHOST}:{a('port')}", "--port", a("sim_port"),
           "--camera-bind", a("camera"), "--server-port", a("server_port"), "--control-port", a("control_port"),
           *shlex.split(a("sim_args"))]
    return [ExecuteProcess(cmd=cmd, name="raf_sim", output="screen", on_exit=Shutdown(reason="raf sim ended"),
                           additional_env={"RAF_MIDDLEWARE": "ros2"})]


def generate_launch_description():
    def arg(name):
        return LaunchConfiguration(name)

    share = FindPackageShare("robotatfactory")
    return LaunchDescription([
        DeclareLaunchArgument("field", default_value="rules2026", description="competition map"),
        DeclareLaunchArgument("sim_args", default_value="--lockstep", description="more raf sim options"),
        DeclareLaunchArgument("rviz", default_value="false", description="start RViz 2 (fixed frame map)"),
        DeclareLaunchArgument("map_to_odom", default_value="first_ground_truth",
                              description="the bridge's map -> odom (none when a localization node runs)"),
        DeclareLaunchArgument("port", default_value=str(BRIDGE_UDP_PORT), description="the bridge's UDP port"),
        DeclareLaunchArgument("sim_port", default_value=str(SIMTWO_UDP_PORT), description="raf sim's command port"),
        DeclareLaunchArgument("control_port", default_value=str(SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET),
                              description="raf sim's control channel, the bridge's sim/* services use it"),
        DeclareLaunchArgument("camera", default_value=f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}",
                              description="the camera's ZMQ endpoint"),
        DeclareLaunchArgument("server_port", default_value=str(SERVER_UDP_PORT),
                              description="factory-state server UDP port"),
        OpaqueFunction(function=_raf_sim),
        GroupAction(scoped=True, actions=[  # the include's arguments stay in it, as in roslaunch
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(PathJoinSubstitution([share, "launch", "ros2", "bridge.launch.py"])),
                launch_arguments={
                    "field": arg("field"),
                    "map_to_odom": arg("map_to_odom"),
                    "port": arg("port"),
                    "camera": arg("camera"),
                    "sim_control": [f"{LOCALHOST}:", arg("control_port")],
                }.items(),
            ),
        ]),
        Node(package="rviz2", executable="rviz2", name="rviz2", arguments=["-f", "map"], output="screen",
             condition=IfCondition(arg("rviz"))),
    ])

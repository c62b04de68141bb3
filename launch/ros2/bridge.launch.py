"""The robotatfactory bridge on ROS 2: SimTwo (or raf sim) <-> ROS topics and TF. The ROS 1 twin is
launch/bridge.launch (the same arguments). Parameters: config/ros2/bridge.yaml (generated from
config/bridge.yaml), then the arguments below; docs/bridge.md lists every one. Several robots: one include
per robot with its own ns, frame_prefix and port.

    ros2 launch robotatfactory bridge.launch.py
    ros2 launch robotatfactory bridge.launch.py sim_host:=192.168.1.20 camera:=tcp://192.168.1.20:9899

Needs a ROS 2 workspace with this package built (docs/ros2.md); without one, `raf --middleware ros2 bridge`
runs the same node.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

from robotatfactory.sim.control import CONTROL_PORT_OFFSET
from robotatfactory.simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SIMTWO_UDP_PORT


def generate_launch_description():
    def arg(name):
        return LaunchConfiguration(name)

    def typed(name, kind):
        return ParameterValue(LaunchConfiguration(name), value_type=kind)

    return LaunchDescription([
        DeclareLaunchArgument("ns", default_value="/", description="namespace of the node and its topics"),
        DeclareLaunchArgument("frame_prefix", default_value="", description="robot1 makes robot1/odom, ..."),
        DeclareLaunchArgument("sim_host", default_value=LOCALHOST,
                              description="accept SensorFrames from this host only ('*': any)"),
        DeclareLaunchArgument("reply_port", default_value="0",
                              description=f"0: reply to the source port; else this port (SimTwo: {SIMTWO_UDP_PORT})"),
        DeclareLaunchArgument("sim_control", default_value=f"{LOCALHOST}:{SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}",
                              description="raf sim's control channel (sim/* services); empty for none"),
        DeclareLaunchArgument("port", default_value=str(BRIDGE_UDP_PORT),
                              description="UDP port the SensorFrames come to"),
        DeclareLaunchArgument("camera", default_value=f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}",
                              description="the camera's ZMQ endpoint"),
        DeclareLaunchArgument("camera_enabled", default_value="true", description="subscribe to the camera"),
        DeclareLaunchArgument("field", default_value="rules2026", description="competition map"),
        DeclareLaunchArgument("map_to_odom", default_value="none",
                              description="none (localization publishes it) | identity | first_ground_truth"),
        DeclareLaunchArgument("config", default_value=PathJoinSubstitution(
            [FindPackageShare("robotatfactory"), "config", "ros2", "bridge.yaml"]),
            description="ROS 2 parameter file (config/ros2/bridge.yaml's shape)"),
        DeclareLaunchArgument("use_sim_time", default_value="true", description="the node's clock is /clock"),
        DeclareLaunchArgument("output", default_value="screen", description="screen or log"),
        DeclareLaunchArgument("clock", default_value="/clock",
                              description="the topic /clock goes to (several robots: one bridge publishes it)"),
        Node(
            package="robotatfactory", executable="bridge_node", name="raf_bridge", namespace=arg("ns"),
            output=arg("output"), additional_env={"RAF_MIDDLEWARE": "ros2"},
            parameters=[arg("config"), {
                "frame_prefix": typed("frame_prefix", str),
                "field": typed("field", str),
                "simulator.host": typed("sim_host", str),
                "simulator.reply_port": typed("reply_port", int),
                "simulator.control": typed("sim_control", str),
                "udp.port": typed("port", int),
                "camera.endpoint": typed("camera", str),
                "camera.enabled": typed("camera_enabled", bool),
                "tf.map_to_odom": typed("map_to_odom", str),
                "topics.clock": typed("clock", str),
                "use_sim_time": typed("use_sim_time", bool),
            }],
        ),
    ])

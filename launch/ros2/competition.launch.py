"""One robot playing one round on the stand-in, on ROS 2: raf sim (realtime, the round's factory-state
server), the bridge, the localization node and the agent (docs/agent.md), which drives on the EKF's pose
only. The ROS 1 twin is launch/competition.launch (the same arguments).

    ros2 launch robotatfactory competition.launch.py round:=3 seed:=2

Ports are sim.launch.py's defaults unless given (sim_port, port, camera, server_port, control_port).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

from robotatfactory.sim.control import CONTROL_PORT_OFFSET
from robotatfactory.simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SERVER_UDP_PORT, SIMTWO_UDP_PORT


def generate_launch_description():
    def arg(name):
        return LaunchConfiguration(name)

    share = FindPackageShare("robotatfactory")
    return LaunchDescription([
        DeclareLaunchArgument("field", default_value="rules2026", description="competition map"),
        DeclareLaunchArgument("round", default_value="1", description="competition round (1, 2, 3)"),
        DeclareLaunchArgument("seed", default_value="0", description="seed of the round and the noise"),
        DeclareLaunchArgument("start_after", default_value="3", description="s before the round starts"),
        DeclareLaunchArgument("sim_extra", default_value="", description="more raf sim options"),
        DeclareLaunchArgument("port", default_value=str(BRIDGE_UDP_PORT), description="the bridge's UDP port"),
        DeclareLaunchArgument("sim_port", default_value=str(SIMTWO_UDP_PORT), description="raf sim's command port"),
        DeclareLaunchArgument("control_port", default_value=str(SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET),
                              description="raf sim's control channel"),
        DeclareLaunchArgument("camera", default_value=f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}",
                              description="the camera's ZMQ endpoint"),
        DeclareLaunchArgument("server_port", default_value=str(SERVER_UDP_PORT),
                              description="factory-state server UDP port"),
        DeclareLaunchArgument("max_input_age", default_value="0.5",
                              description="s after which pose/odom count as stale (the robot stops)"),
        DeclareLaunchArgument("rviz", default_value="false", description="start RViz 2"),
        # each include in a scoped group: its arguments (and the defaults it declares, e.g. config) stay in it,
        # as in roslaunch; otherwise the bridge's config file would become the localization's
        GroupAction(scoped=True, actions=[
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(PathJoinSubstitution([share, "launch", "ros2", "sim.launch.py"])),
                launch_arguments={
                    "field": arg("field"),
                    "sim_args": ["--realtime --round ", arg("round"), " --seed ", arg("seed"), " --start-after ",
                                 arg("start_after"), " ", arg("sim_extra")],
                    "map_to_odom": "none",
                    "port": arg("port"),
                    "sim_port": arg("sim_port"),
                    "control_port": arg("control_port"),
                    "camera": arg("camera"),
                    "server_port": arg("server_port"),
                    "rviz": arg("rviz"),
                }.items(),
            ),
        ]),
        GroupAction(scoped=True, actions=[
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(PathJoinSubstitution([share, "launch", "ros2", "localization.launch.py"])),
                launch_arguments={"field": arg("field")}.items(),
            ),
        ]),
        Node(
            package="robotatfactory", executable="agent_node", name="raf_agent", output="screen",
            additional_env={"RAF_MIDDLEWARE": "ros2"},
            parameters=[{
                "field": ParameterValue(arg("field"), value_type=str),
                "server.port": ParameterValue(arg("server_port"), value_type=int),
                "max_input_age": ParameterValue(arg("max_input_age"), value_type=float),
                "use_sim_time": True,
            }],
        ),
    ])

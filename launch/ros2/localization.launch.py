"""The robotatfactory localization on ROS 2: ArUco camera fixes, odometry and LIDAR beacons fused by an EKF;
publishes pose, camera_pose, aruco/*, map -> odom and /diagnostics. The ROS 1 twin is
launch/localization.launch (the same arguments). Parameters: config/ros2/localization.yaml (generated from
config/localization.yaml), docs/localization.md. Run it next to the bridge with the same ns/frame_prefix.

    ros2 launch robotatfactory localization.launch.py
    ros2 launch robotatfactory localization.launch.py initial_pose:=start use_lidar:=false
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    def arg(name):
        return LaunchConfiguration(name)

    def typed(name, kind):
        return ParameterValue(LaunchConfiguration(name), value_type=kind)

    return LaunchDescription([
        DeclareLaunchArgument("ns", default_value="/", description="namespace of the node and its topics"),
        DeclareLaunchArgument("frame_prefix", default_value="", description="robot1 makes robot1/odom, ..."),
        DeclareLaunchArgument("field", default_value="rules2026", description="competition map"),
        DeclareLaunchArgument("config", default_value=PathJoinSubstitution(
            [FindPackageShare("robotatfactory"), "config", "ros2", "localization.yaml"]),
            description="ROS 2 parameter file (config/ros2/localization.yaml's shape)"),
        DeclareLaunchArgument("initial_pose", default_value="none",
                              description="none: wait for a confident camera fix; start: the field's start pose"),
        DeclareLaunchArgument("use_lidar", default_value="true", description="LIDAR beacon updates"),
        DeclareLaunchArgument("filter_method", default_value="planar",
                              description="camera fixes the EKF uses: planar | all_pnp | closest_checked"),
        DeclareLaunchArgument("use_sim_time", default_value="true", description="the node's clock is /clock"),
        DeclareLaunchArgument("output", default_value="screen", description="screen or log"),
        Node(
            package="robotatfactory", executable="localization_node", name="raf_localization",
            namespace=arg("ns"), output=arg("output"), additional_env={"RAF_MIDDLEWARE": "ros2"},
            parameters=[arg("config"), {
                "frame_prefix": typed("frame_prefix", str),
                "field": typed("field", str),
                "node.initial_pose": typed("initial_pose", str),
                "node.use_lidar": typed("use_lidar", bool),
                "node.filter_method": typed("filter_method", str),
                "use_sim_time": typed("use_sim_time", bool),
            }],
        ),
    ])

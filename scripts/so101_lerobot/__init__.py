"""The SO-101 ROS 2 stack's way to LeRobot: episode bags written by recorder_node (rosbag2 MCAP)
become LeRobot datasets (codebase v3.0) through LeRobot's own LeRobotDataset API."""

"""Inputs and outputs: input sources (datasets), ground truth files (groundtruth), the MCAP
session log and its replay (session), and the output formats: TUM (tum), trajectory.csv
(trajectory_csv), ROS 2 bags (ros2_output), the overlay image (overlay), message fields both
logs share (messages), dropped-frame accounting (drops)."""

"""Frame sources: videos, image folders, ROS 1/2 bags and MCAP files read as frames
with their time stamps (``base``), for replay, camera fit and evaluate --frames."""

"""Recordings out: a run as MCAP or a ROS 2 bag (Foxglove- and RViz-readable)."""

"""Live runs: sources of rows as they arrive (a log directory being written, ROS 2 topics),
sinks of poses (ROS 2 topics, a Foxglove live view)."""

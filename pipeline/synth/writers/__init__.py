"""Writers of synthetic telemetry and video in the formats real vehicles write (tlog, ROS 1/2 bags, MCAP, mp4)."""

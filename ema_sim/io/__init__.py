"""Data in and out: the measured-data CSV contract (and, with the node suite, rosbag2)."""

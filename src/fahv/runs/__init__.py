"""Recorded runs.

rosbag2/MCAP files, metrics, inspect/export/compare, plots, the SIL runner and replay.
"""

"""Recorded runs.

rosbag2/MCAP files, metrics, inspect/export/compare, plots, replay (the SIL runner is
`fahv.sil.runner`).
"""

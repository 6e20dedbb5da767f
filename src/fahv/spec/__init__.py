"""Design files, scenario files and run specs: their schemas, loading and the stored designs.

What the loop and the ROS nodes may import: no module here imports the design's
computations (`fahv.bounds`, `fahv.tube`, `fahv.onset`,
`fahv.certificate`, `fahv.design`).
"""

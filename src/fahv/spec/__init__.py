"""Design files, scenario files and run specs: their schemas, loading and the stored designs.

What the loop and the ROS nodes may import: no module here imports the design's
computations (:mod:`fahv.bounds`, :mod:`fahv.tube`, :mod:`fahv.onset`,
:mod:`fahv.certificate`, :mod:`fahv.design`).
"""

"""The closed loop.

the graph table, the per-node cores shared by nodes and simulator, node parameters, in-
process simulation.
"""

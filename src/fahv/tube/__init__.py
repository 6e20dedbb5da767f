"""Tubes and their synthesis: F and Z (LMI 24-28), the tube set (W_8, Z_8), the notch loops.

The vertex tube checked over its domain, the eight-state tube set and its closure, the
tube loop through the notch filter and a gain designed for it, the QP's rows that keep
the nominal inside the tube set's range, the input room and the tube's feasibility.
"""

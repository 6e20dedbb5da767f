"""Probabilistic reachable sets of the loop on the state estimate.

`error_bound`: the gain-scheduled Kalman filter's a-posteriori error system at every
pair of model and gain vertex, a common covariance bound of its noise-driven part (LMI,
re-checked exactly) and the exact worst cases at the frozen vertices. `closed_loop`: the
joint system of the tube law on the estimate and the filter's error, and its covariance
bound: the probabilistic reachable set (Hewing and Zeilinger, CDC 2018) that the
estimate design (`fahv.design.estimate`) tightens the nominal with.
"""

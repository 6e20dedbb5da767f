"""Bounds of the Kalman filter's error and of the loop on the estimate (a study).

`error_bound` (the filter's error system and its covariance and peak-to-peak bounds),
`output_feedback` (the set-based output-feedback tube the sensors would need),
`closed_loop` (the probabilistic tube of the loop on the estimate) and `study` (what
`fahv-studies estimation` prints, gathered).
"""

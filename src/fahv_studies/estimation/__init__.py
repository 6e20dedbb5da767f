"""Bounds of the Kalman filter's error and of the loop on the estimate (a study).

The filter's error system and the probabilistic tube of the loop on the estimate are
the product's (`fahv.stochastic`); here: `output_feedback` (the set-based
output-feedback tube the sensors would need) and `study` (what `fahv-studies
estimation` prints, gathered).
"""

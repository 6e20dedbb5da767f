"""The online nominal tracking MPC (nominal source `mpc`), one concept per module.

The nominal part of the tube-based MPC in the tracking form with an artificial steady
state of Limon et al. (2010, "Robust tube-based MPC for tracking"), on the nominal LPV
model of eq. (12) of Yang et al. (2022):

- `fahv.control.mpc.settings`: the case file's `mpc` section and
  `fahv.control.mpc.settings.MPCSettings` (horizon, rates, weights, boxes);
- `fahv.control.mpc.attitude`: the QP's attitude bounds, the requirement less
  the tube's support;
- `fahv.control.mpc.estimator`: the state-disturbance estimate and the
  steady-state shift it implies;
- `fahv.control.mpc.qp_layout`: the condensed QP's decision vector, predictions,
  cost and rows;
- `fahv.control.mpc.tracking`: one run's QP,
  `fahv.control.mpc.tracking.TrackingMPC` (scheduling and solving);
- `fahv.control.mpc.nominal_source`: the nominal source of B runs,
  `fahv.control.mpc.nominal_source.TrackingMPCNominal` (registry entry `mpc`).
"""

"""fahv: Tube-MPC via notch filter for a flexible air-breathing hypersonic vehicle.

A pure-Python library (no ROS import) implementing Yang et al. 2022, "Tube-MPC
control via notch filter for flexible air-breathing hypersonic vehicle with actuator
fault": the coupling, decoupled and extended models (eq. 1-4, 40), trim,
linearisation, the tensor-product polytopic LPV model (eq. 11-12) and the notch
filter (eq. 37-39).
"""

import os

# Reproducible numbers: one BLAS/OpenMP thread unless the environment says otherwise.
# Set before numpy is imported by any fahv module (the `fahv` command, the ROS nodes
# and the Dask workers import fahv first); a multi-threaded BLAS may sum in another
# order from run to run. Recorded in every design's provenance (`blas_threads`).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"

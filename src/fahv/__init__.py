"""fahv: Tube-MPC via notch filter for a flexible air-breathing hypersonic vehicle.

A pure-Python library (no ROS import) implementing Yang et al. 2022, "Tube-MPC
control via notch filter for flexible air-breathing hypersonic vehicle with actuator
fault": the coupling, decoupled and extended models (eq. 1-4, 40), trim,
linearisation, the tensor-product polytopic LPV model (eq. 11-12) and the notch
filter (eq. 37-39).
"""

__version__ = "0.1.0"

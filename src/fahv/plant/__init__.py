"""The simulated vehicle.

RK4 integration of the nonlinear CM, actuator limits, fault registry, parameter
uncertainty (sec. 5.1).
"""

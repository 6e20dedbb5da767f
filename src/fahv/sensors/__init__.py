"""Sensor models: the measurement y the controllers will read instead of the state.

Channels h, V, theta, q (rate gyro, which sees the flexible modes through the mode
slopes at its location) and optionally alpha (air data), each with Gaussian noise,
biases, delay, lag, sample-and-hold and quantisation (`fahv.sensors.data`); the
counter-based generator that makes every draw a function of (seed, channel, step)
(`fahv.sensors.philox`); the sensor fault kinds (`fahv.sensors.faults`); the
measurement of B runs and the noise bound of a run (`fahv.sensors.measure`).
"""

"""Notch filter, nominal trajectory and controller nodes (adapters of fahv.loop.cores)."""

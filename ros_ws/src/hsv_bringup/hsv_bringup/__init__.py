"""Recorder, replay and the SIL runner of the graph."""

"""Offline design of a case.

case files, disturbance set W (eq. 13-19), the pipeline to certified artefacts with
provenance.
"""

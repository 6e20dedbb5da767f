"""Vehicle models.

data file, CM/DM/ECM (eq. 1-4, 40), trim, linearisation, TP polytopic LPV model (eq.
11-12), notch filter (eq. 37-39).
"""

"""Analyses of a stored design: the classical loop margins of the tube controller.

The tube loop u = v + F e linearised with the constraints inactive, broken at the
elevator input delta_e or at the pitch-rate sensor q, with and without the notch filter
on q, over the design point, the LPV vertices and the parameter box corners
(`fahv.analysis.margins`), its table (`fahv.analysis.margin_report`) and
its Bode and Nichols figures (`fahv.analysis.margin_figures`).
"""

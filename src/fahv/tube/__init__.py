"""Tube design of Yang et al. 2022 sec. 3.2 and 4.3.

* :mod:`.disturbance` -- lumped disturbance set W, eq. (13)-(19)
* :mod:`.feedback` -- robust feedback gain F (LMI 24) and invariant tube Z (eq. 25-28)
* :mod:`.nominal` -- nominal gain K, LMI (32)-(35) / (49)-(52), tightened inputs (eq. 30)

Every design function works in scaled coordinates (x / D_x, u / D_u), returns
unscaled results, and re-checks its certificate numerically; a certificate that does
not hold raises :class:`fahv.errors.DesignError`.
"""

"""The certificate of a design: its re-check from the stored arrays and its printed lines.

:mod:`fahv.certificate.verify` re-checks a stored design without a solver;
:mod:`fahv.certificate.report` formats the lines a design prints (formatting only).
"""

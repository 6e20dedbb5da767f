"""The certificate of a design: its re-check from the stored arrays and its printed lines.

`fahv.certificate.verify` re-checks a stored design without a solver;
`fahv.certificate.report` formats the lines a design prints (formatting only).
"""

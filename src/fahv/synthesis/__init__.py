"""Numerics below every layer.

LMI scaling and checks, tube (LMI 24) and nominal (LMI 32-35) synthesis and their
certificates, invariant ellipsoids of fixed loops, the exact RPI level (trust-region
dual), the off-line RMPC ellipsoids and the QP's KKT check, on polytopic vertex matrices.
"""

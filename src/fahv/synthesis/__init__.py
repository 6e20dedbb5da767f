"""Numerics below every layer.

LMI scaling and checks, tube (LMI 24) and nominal (LMI 32-35) synthesis and their
certificates, on polytopic vertex matrices.
"""

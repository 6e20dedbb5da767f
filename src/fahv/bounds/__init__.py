"""The disturbance W and the domain it is bounded over (eq. 13-19).

The sampled W, the domains (scheduling box, nominal box, the vertex tube's domain), the
vertex sets (faults, adjustable gains, the error along the nominal), one plant step, the
deterministic one-step bound (Taylor and integral form), the loss coverage and the
tube's share of the input rate (`fahv.bounds.input_rate`).
"""

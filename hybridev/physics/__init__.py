"""Physics layer: parameter sets, kinematic speed traces, force balance, climate load,
trip tables, sufficient statistics and the synthetic ground truths.

Imports only :mod:`hybridev.core`; never torch, scikit-learn or anything above it.
"""

"""Learning layer: features, residual networks, conformal calibration, predictive
distributions, the :class:`~hybridev.learning.model.HybridModel`, its persistence and
the baselines.

Imports the layers below it (core, physics, data, bayes, metrics).
"""

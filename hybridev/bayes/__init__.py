"""Bayesian calibration layer: priors, likelihood, emcee sampling, the physics posterior and
the model-discrepancy stage (:mod:`hybridev.bayes.discrepancy`).

Imports the layers below it (core, physics, data); never torch.
"""

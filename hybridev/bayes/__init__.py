"""Bayesian calibration layer: priors, likelihood, emcee sampling and the physics posterior.

Imports the layers below it (core, physics, data); never torch.
"""

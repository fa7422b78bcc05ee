"""Warnings and errors shared by the layers (the bottom of the import graph).

Every layer raises :class:`ValueError` for bad input (naming the field, the value
and the allowed range); the classes here are the package's own warnings, kept in
one small module so that no layer has to import another to raise or catch them.
"""

from __future__ import annotations

__all__ = ["CalibrationWarning", "ConvergenceWarning", "DataWarning", "OutOfDomainWarning",
           "PhysicsFallbackWarning", "RecoveryWarning"]


class ConvergenceWarning(UserWarning):
    """The MCMC chain is shorter than 50 autocorrelation times."""


class PhysicsFallbackWarning(UserWarning):
    """A prediction used the physics model only, because no network was fitted."""


class OutOfDomainWarning(UserWarning):
    """Some trips lie outside the conditions the model was trained on (see ``in_domain``)."""


class CalibrationWarning(UserWarning):
    """The measured trips are too few (or too few groups) to calibrate the usual levels."""


class DataWarning(UserWarning):
    """Input is used, but with less than it could carry (e.g. a trip without its logged trace)."""


class RecoveryWarning(UserWarning):
    """A leftover of an interrupted earlier run was cleaned up or restored (what was done)."""

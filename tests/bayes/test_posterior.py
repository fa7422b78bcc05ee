"""Burn-in and thinning of an emcee run (:func:`hybridev.bayes.posterior.burn_and_thin`)."""

import numpy as np


def test_burn_and_thin_leave_out_a_coordinate_without_an_autocorrelation_time():
    """emcee can return NaN for a coordinate's autocorrelation time; burn-in and thinning
    then come from the others (it used to stop the fit: ``ceil(nan)``)."""
    from hybridev.bayes.posterior import burn_and_thin

    assert burn_and_thin([12.0, np.nan, 4.0], 200) == (12.0, 36, 2)
    assert burn_and_thin([80.0, 3.0], 200) == (80.0, 100, 1)  # burn at most half
    assert burn_and_thin([np.nan, np.inf], 200) == (200.0, 100, 1)  # none: unconverged

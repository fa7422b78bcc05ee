"""What ``fit_info_`` says about the data: the fit's outlier trips and the data quality.

:func:`outlier_notes` turns the physics posterior's outlier table
(``PhysicsPosterior.outliers_``, :mod:`hybridev.bayes.outliers`) into a small
JSON-serialisable record; :func:`quality_notes` gives the totals of
:func:`hybridev.data.quality.data_quality` of the fitted
:class:`~hybridev.data.logs.MeasuredTrips`. :meth:`hybridev.HybridModel.fit` stores them
as ``fit_info_["outliers"]`` and ``fit_info_["data_quality"]``; the calibration report
and the command line show them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

__all__ = ["MAX_LISTED", "fit_notes", "outlier_notes", "quality_notes"]

MAX_LISTED = 50
"""At most this many outlier trips are listed (``n_outliers`` counts them all)."""
_REJECTED = ["source", "row", "trip_id", "field", "value", "reason"]


def _plain(v):
    """A JSON-serialisable scalar (numpy scalars to Python, NaN to None)."""
    v = v.item() if isinstance(v, np.generic) else v
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v if isinstance(v, (str, int, float, bool, type(None))) else str(v)


def outlier_notes(posterior) -> dict | None:
    """``{"n_outliers", "trips": [{trip_id, reason, residual_rel, z}, ...]}`` of a posterior.

    Only the trips flagged ``outlier`` (at most :data:`MAX_LISTED`, largest ``|z|``
    first); None without a posterior.
    """
    if posterior is None:
        return None
    table = posterior.outliers_
    flagged = table[table["outlier"].astype(bool)] if len(table) else table
    order = np.argsort(-np.abs(flagged["z"].to_numpy(float)), kind="stable")
    rows = [{"trip_id": _plain(r["trip_id"]), "reason": str(r["reason"]),
             "residual_rel": _plain(round(float(r["residual_rel"]), 4)),
             "z": _plain(round(float(r["z"]), 2))}
            for _, r in flagged.iloc[order[:MAX_LISTED]].iterrows()]
    return {"n_outliers": len(flagged), "trips": rows}


def quality_notes(measured, posterior=None) -> dict | None:
    """Totals of :func:`hybridev.data.quality.data_quality` (None unless ``measured`` is a
    :class:`~hybridev.data.logs.MeasuredTrips`); with a posterior, its outliers counted."""
    from hybridev.data.logs import MeasuredTrips
    from hybridev.data.quality import data_quality

    if not isinstance(measured, MeasuredTrips):
        return None
    rej = measured.rejected
    if rej is None or not set(_REJECTED) <= set(rej.columns):  # a MeasuredTrips made by hand
        measured = dataclasses.replace(measured, rejected=pd.DataFrame(
            rej if rej is not None else None).reindex(columns=_REJECTED))
    outliers = None if posterior is None else posterior.outliers_
    totals = data_quality(measured, outliers).totals
    return {k: ({str(a): _plain(b) for a, b in v.items()} if isinstance(v, dict) else _plain(v))
            for k, v in totals.items()}


def fit_notes(measured, posterior) -> dict:
    """``{"outliers": ..., "data_quality": ...}`` for ``fit_info_`` (absent keys left out)."""
    notes = {"outliers": outlier_notes(posterior), "data_quality": quality_notes(measured,
                                                                                 posterior)}
    return {k: v for k, v in notes.items() if v is not None}

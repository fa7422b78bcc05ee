"""CSV cells a spreadsheet would run as formulas, neutralised (used by :mod:`hybridev.core.outputs`).

A text cell starting with ``=``, ``+``, ``-``, ``@``, a tab or a carriage
return (a trip id such as ``=HYPERLINK(...)``) is run as a formula by
spreadsheet programs when the CSV is opened; it is written with a leading
``'``. Numbers, and text that is a number (``"-5"``), are untouched.
"""

from __future__ import annotations

__all__ = ["neutralise_formulas"]


_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _defuse(v):
    if not isinstance(v, str) or not v.startswith(_FORMULA_START):
        return v
    try:
        float(v)
        return v  # a number written as text ("-5") is not a formula
    except ValueError:
        return "'" + v


def neutralise_formulas(df):
    """Text cells a spreadsheet would run as a formula (``=``, ``+``, ``-``, ``@``, tab or
    carriage return first, and not a number) get a leading ``'``; numbers are untouched.

    Examples
    --------
    >>> import pandas as pd
    >>> neutralise_formulas(pd.DataFrame({"id": ["=1+2", "-5", "a"], "x": [-1.0, 2, 3]}))["id"].tolist()
    ["'=1+2", '-5', 'a']
    """
    text = [c for c in df.columns
            if df[c].dtype == object or str(df[c].dtype) in ("string", "str")]
    if not text:
        return df
    out = df.copy(deep=False)
    for c in text:
        out[c] = df[c].map(_defuse)
    renamed = {c: _defuse(c) for c in out.columns if isinstance(c, str)}
    return out.rename(columns=renamed)

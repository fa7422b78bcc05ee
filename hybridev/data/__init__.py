"""Measured-data layer: validation of measured-trip tables and logged time series,
and reading them from CSV or Parquet.

Imports :mod:`hybridev.core` and :mod:`hybridev.physics` only.
"""

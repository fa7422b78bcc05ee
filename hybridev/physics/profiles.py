"""Driving-behaviour profiles: the paper's three modes and the logged-trace profile.

Split from :mod:`hybridev.physics.params` (which re-exports every name here, so
``from hybridev.physics.params import PROFILES`` keeps working). Also holds
:func:`_check_range`, the field-range check both parameter classes share.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

__all__ = ["LOGGED_PROFILE", "PROFILES", "DrivingProfile", "ProfileLike", "get_profile"]


def _check_range(owner: str, name: str, value: float, lo: float, hi: float,
                 *, lo_open: bool = False, hi_open: bool = False) -> None:
    """Raise a ValueError naming the field, value and allowed range."""
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        value = value.item()  # numpy scalar -> Python number, for a plain message
    try:
        ok = not isinstance(value, bool) and math.isfinite(value)
    except TypeError:
        ok = False
    if ok:
        ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    if not ok:
        lb = "(" if lo_open else "["
        rb = ")" if hi_open else "]"
        raise ValueError(f"{owner}.{name}={value!r} is outside the allowed range {lb}{lo}, {hi}{rb}")



@dataclass(frozen=True)
class DrivingProfile:
    """A driving-behaviour profile (the paper's Table "Driving Profiles").

    Parameters
    ----------
    name : str
        Profile name (``"eco"``, ``"normal"``, ``"aggressive"`` or your own).
    max_accel_mps2 : float
        Largest |acceleration| a synthesised trace may use, m/s^2.
    efficiency_multiplier : float
        Multiplies battery traction power (>1 means less efficient driving).
    regen_efficiency : float
        Fraction of negative wheel power returned to the battery, in [0, 1].
    aux_kw : float
        Mode-specific auxiliary power ``P_m`` in kW.
    phase_fractions : tuple of 3 float
        Share of time spent accelerating, cruising and braking; sums to 1.
    pke_mps2 : float
        Target positive kinetic energy per metre (m/s^2) of synthesised
        traces: the standard measure of how much speed variation a driver
        adds. Not in the paper; chosen so that the paper's baseline-scenario
        table is reproduced (see ``evaluation/physics_reproduction/physics_reproduction.md``).
    cycle_period_s : float
        Nominal duration of one accelerate-cruise-brake cycle, s.
    amplitude_cv : float
        Coefficient of variation of the per-cycle speed-swing amplitude: the
        random speed perturbation, growing with aggressiveness.
    source : str
        Where the values come from (free text, not compared).

    Examples
    --------
    >>> from hybridev import PROFILES
    >>> PROFILES["eco"].regen_efficiency
    0.75
    """

    name: str
    max_accel_mps2: float
    efficiency_multiplier: float
    regen_efficiency: float
    aux_kw: float
    phase_fractions: tuple[float, float, float]
    pke_mps2: float = 0.15
    cycle_period_s: float = 40.0
    amplitude_cv: float = 0.3
    source: str = field(default="user-defined", compare=False)

    def __post_init__(self) -> None:
        o = f"DrivingProfile({self.name!r})"
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"DrivingProfile.name={self.name!r} must be a non-empty string")
        _check_range(o, "max_accel_mps2", self.max_accel_mps2, 0.0, 15.0, lo_open=True)
        _check_range(o, "efficiency_multiplier", self.efficiency_multiplier, 0.0, 5.0, lo_open=True)
        _check_range(o, "regen_efficiency", self.regen_efficiency, 0.0, 1.0)
        _check_range(o, "aux_kw", self.aux_kw, 0.0, 50.0)
        _check_range(o, "pke_mps2", self.pke_mps2, 0.0, 5.0)
        _check_range(o, "cycle_period_s", self.cycle_period_s, 0.0, 3600.0, lo_open=True)
        _check_range(o, "amplitude_cv", self.amplitude_cv, 0.0, 2.0)
        try:
            pf = tuple(float(x) for x in self.phase_fractions)
        except (TypeError, ValueError):
            pf = ()
        if len(pf) != 3 or any(not (0.0 < x < 1.0) for x in pf) or abs(sum(pf) - 1.0) > 1e-6:
            raise ValueError(f"{o}.phase_fractions={self.phase_fractions!r} must be three values "
                             "in (0, 1) (accel, cruise, brake) that sum to 1")
        object.__setattr__(self, "phase_fractions", pf)


_PAPER = "Paper, Table 'Parameters of Three Typical Driving Profiles'"
_TUNED = "; pke/cycle/cv: hybridev, tuned to the paper's baseline-scenario table"

PROFILES: Mapping[str, DrivingProfile] = MappingProxyType({
    "eco": DrivingProfile("eco", 1.5, 0.85, 0.75, 0.0, (0.20, 0.65, 0.15),
                          pke_mps2=0.10, cycle_period_s=60.0, amplitude_cv=0.15,
                          source=_PAPER + _TUNED),
    "normal": DrivingProfile("normal", 2.5, 1.00, 0.65, 0.5, (0.30, 0.50, 0.20),
                             pke_mps2=0.16, cycle_period_s=45.0, amplitude_cv=0.30,
                             source=_PAPER + _TUNED),
    "aggressive": DrivingProfile("aggressive", 4.0, 1.35, 0.50, 1.5, (0.40, 0.35, 0.25),
                                 pke_mps2=0.17, cycle_period_s=30.0, amplitude_cv=0.45,
                                 source=_PAPER + _TUNED),
})
"""The paper's three driving profiles, keyed by mode name (read-only)."""


LOGGED_PROFILE = DrivingProfile(
    "logged", max_accel_mps2=4.0, efficiency_multiplier=1.0, regen_efficiency=0.65,
    aux_kw=0.0, phase_fractions=(0.3, 0.5, 0.2),
    source="hybridev: a logged speed trace already holds the driving style, so no "
           "efficiency multiplier and no mode auxiliary power; regen efficiency of the "
           "paper's 'normal' profile (calibrated through regen_scale)")
"""Profile of a trip with a logged trace and no ``mode`` label (not a key of PROFILES)."""


def get_profile(mode: str | DrivingProfile) -> DrivingProfile:
    """Return the profile for a mode name, or the profile itself.

    Raises
    ------
    ValueError
        If the name is not a key of :data:`PROFILES`.

    Examples
    --------
    >>> get_profile("normal").efficiency_multiplier
    1.0
    """
    if isinstance(mode, DrivingProfile):
        return mode
    try:
        return PROFILES[mode]
    except (KeyError, TypeError):
        raise ValueError(f"mode={mode!r} is not a known driving profile; "
                         f"allowed: {sorted(PROFILES)}") from None


ProfileLike = DrivingProfile | str | Sequence[DrivingProfile | str]
"""A driving profile, its name, or one per trip."""

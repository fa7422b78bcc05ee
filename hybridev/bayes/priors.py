"""Priors of the physics calibration: which parameters are sampled and their prior laws.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybridev.physics.params import LOGGED_PROFILE, PROFILES
from hybridev.physics.stats import STAT_PARAMS

__all__ = ["CLIMATE_PARAMS", "DEFAULT_PARAMS", "REGEN_EFFICIENCY_MAX", "PhysicsPrior"]

REGEN_EFFICIENCY_MAX = max(p.regen_efficiency for p in (*PROFILES.values(), LOGGED_PROFILE))
"""Highest warm-weather regen efficiency of any profile (0.75, ``eco``).

``regen_scale`` is bounded by its inverse, so that no profile regenerates more than
its braking energy at any temperature. The bound is taken from the profiles, not
from the trips' statistics: there the cold factors
(:func:`hybridev.physics.thermal.cold_factors`) have already lowered the regen
efficiency, and a bound taken from a winter log would let a posterior fitted on cold
trips regenerate more than the braking energy on warm ones."""


DEFAULT_PARAMS = ("drag_area_m2", "rolling_resistance_coef", "drivetrain_efficiency",
                  "aux_base_kw", "regen_scale")
"""Parameters calibrated by default: road load, efficiency, base auxiliary
power and regeneration."""

CLIMATE_PARAMS = ("heating_scale", "cooling_scale", "warmup_scale", "heating_offset_k")
"""Climate parameters (steady heating power, steady cooling power, warm-up energy
scales, and the driver's heating onset) that
:func:`hybridev.bayes.sampler.calibrate_physics` adds to the sampled set by
default when the vehicle uses the continuous climate model."""


@dataclass(frozen=True)
class PhysicsPrior:
    """Prior of the calibrated physics parameters, centred on the nominal vehicle.

    Widths are the project's choice (stated here; change them with
    :func:`dataclasses.replace`): data-sheet values of ``C_dA`` and ``C_r``
    are rarely more than 20-30 % off for a real car (tyres, load, wind);
    a measured coast-down (``vehicle.road_load_source == "coastdown"``,
    set by :meth:`~hybridev.physics.params.VehicleParams.from_coastdown`)
    pins them to ~10 % (repeatability of coast-down tests and the spread of
    road conditions: wind, surface, tyre temperature), so that the climate
    and auxiliary terms take up what the road load does not explain.
    Efficiency is known to a few points, auxiliary load only to a factor of
    ~1.6, the climate load (cabin ``UA``, set point) to a factor of ~2.2,
    the warm-up energy (cabin heat capacity, soak state: a car parked in
    a garage needs less) to a factor of ~2, and the temperature at which a
    driver starts heating to ~5 K.

    Parameters
    ----------
    drag_area_log_sd : float
        ``log C_dA ~ N(log nominal, sd)``: lognormal, 0.25 ~ 25 %.
    rolling_resistance_log_sd : float
        Same for ``C_r``.
    linear_drag_sd_n_per_mps : float, N/(m/s)
        ``b ~ N(nominal, sd)`` truncated to ``b >= 0``.
    efficiency_sd : float
        ``eta_d ~ N(nominal, sd)`` truncated to ``efficiency_bounds`` (open).
    efficiency_bounds : tuple of 2 float
    aux_log_sd : float
        ``log P_b ~ N(log nominal, sd)``; needs a nominal ``P_b > 0``. The same
        for the drive loss ``drive_loss_kw``.
    hvac_log_sd : float
        ``log hvac_scale ~ N(0, sd)``; the scale multiplies the climate power
        (all four HVAC bands, or the continuous model's steady power); the
        same prior for ``heating_scale`` and ``cooling_scale`` (the heating
        and cooling parts alone). 0.8: 99 % of the prior within a factor 7.9
        either way, because how much of the modelled load a driver uses
        (air vs seat heating, A/C vs open windows, set point) varies that
        much between cars and drivers (AAA 2019: HVAC on/off changes cold
        range by 29 points). The published car-to-car spread lies well
        inside it: ADAC/Green NCAP 2024 measured +38 % to +100 % energy at
        -7 °C on the WLTC (battery heating included), i.e. heating shares
        from ~0.5 of the PTC default up to the heater's rating, and a heat
        pump (COP 2-3 at 0-15 °C) draws a share of 0.33-0.5. It is not
        widened: the one published fleet curve that stays nearly flat in
        mild cold (Tesla Model S down to -4 °C, FleetCarma 2016) is
        explained by battery and cabin conditioning between trips, energy
        that a trip's measurement does not contain. A driver who does not
        heat in mild weather is the heating *onset*'s to explain
        (``heating_offset_k``, below), not this scale's; a posterior share
        below ~1/8 (a car preconditioned while parked) is flagged by the
        calibration report rather than absorbed by a wider prior.
    warmup_log_sd : float
        ``log warmup_scale ~ N(0, sd)``; the scale multiplies the warm-up energy.
    heating_offset_sd_k : tuple of 2 float, K
        ``heating_offset_k`` (how far below the physical balance point, 17.4
        °C by default, a driver starts heating) has a split-normal prior
        centred on the nominal value: sd ``(below, above)`` = (2, 5) K,
        truncated to ``heating_offset_bounds_k``; 99 % of it lies in about
        [-4.8, +13.5] K. Later onsets (positive) are the wide side: clothing
        (a coat is about one clo more than indoor clothing, 6-8 K of
        comfortable temperature at sedentary activity, ASHRAE 55) and daytime
        sun through the glazing (0 to ~1 kW, 0-9 K at the default cabin
        ``UA``). Earlier onsets (negative) need a warmer set point (+-1.5 K
        between drivers) or fewer gains than the default's (no sun at night:
        ~2 K), so that side is narrow: a wide one let a car trained on warm
        trips only (20-28 °C) explain a little unmodelled energy there as
        heating from 24 °C and then over-predict its cool trips with narrow
        intervals (``evaluation/shift_and_small_data``, M1 warm-trained
        folds). The onset separates *when* a car heats, which mild-weather
        trips pin down, from *how much* a cold cabin needs
        (``heating_scale``): a car logged at 5-15 °C that barely heats then
        keeps a physical heating slope for winter instead of a tiny scale
        that would also apply at -15 °C.
    heating_offset_bounds_k : tuple of 2 float, K
        Support of ``heating_offset_k`` relative to the nominal value.
    coastdown_log_sd : float
        Replaces ``drag_area_log_sd`` and ``rolling_resistance_log_sd`` when
        the vehicle's road load comes from a coast-down.
    group_sd_scale : float
        Prior of the day/session random effect's relative sd ``tau`` (when
        the calibration has ``groups``): half-normal with this scale.
    regen_scale_sd : float
        ``s ~ N(1, sd)`` truncated to ``(0, 1 / max eta_r)`` so that no
        profile regenerates more than the braking energy.
    noise_rel_bounds : tuple of 2 float
        ``sigma_rel`` log-uniform on this range (scale-free).
    noise_dof : float or None
        Degrees of freedom ``nu`` of the Student-t likelihood of the relative
        energy residual (:mod:`hybridev.bayes.likelihood`), > 2; ``None``: the
        normal likelihood. 4 by default, the usual robust choice (Lange, Little
        & Taylor, JASA 84, 1989): a trip 10 sd off weighs about 5 % of a typical
        one in the fit, so a wrong SoC reading or a trip that charged on the way
        neither zeroes nor drags the posterior. With groups the day effect and
        the trips' noise are jointly multivariate t per group.

    Examples
    --------
    >>> import dataclasses
    >>> wide = dataclasses.replace(PhysicsPrior(), drag_area_log_sd=0.5)
    >>> wide.drag_area_log_sd
    0.5
    """

    drag_area_log_sd: float = 0.25
    rolling_resistance_log_sd: float = 0.25
    linear_drag_sd_n_per_mps: float = 2.0
    efficiency_sd: float = 0.05
    efficiency_bounds: tuple[float, float] = (0.5, 1.0)
    aux_log_sd: float = 0.5
    hvac_log_sd: float = 0.8
    warmup_log_sd: float = 0.7
    heating_offset_sd_k: tuple[float, float] = (2.0, 5.0)
    heating_offset_bounds_k: tuple[float, float] = (-10.0, 20.0)
    coastdown_log_sd: float = 0.10
    group_sd_scale: float = 0.05
    regen_scale_sd: float = 0.2
    noise_rel_bounds: tuple[float, float] = (1e-3, 0.5)
    noise_dof: float | None = 4.0
    source: str = field(default="hybridev defaults (see class docstring)", compare=False)

    def __post_init__(self) -> None:
        for name in ("drag_area_log_sd", "rolling_resistance_log_sd", "linear_drag_sd_n_per_mps",
                     "efficiency_sd", "aux_log_sd", "hvac_log_sd", "regen_scale_sd",
                     "warmup_log_sd", "coastdown_log_sd", "group_sd_scale"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"PhysicsPrior.{name}={v!r} is outside the allowed range "
                                 "(0, inf)")
        if self.noise_dof is not None and not (np.isfinite(self.noise_dof)
                                               and 2.0 < self.noise_dof <= 1000.0):
            raise ValueError(f"PhysicsPrior.noise_dof={self.noise_dof!r} is outside the allowed "
                             "range (2, 1000] (None: normal likelihood)")
        lo, hi = (float(x) for x in self.efficiency_bounds)
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"PhysicsPrior.efficiency_bounds={self.efficiency_bounds!r} must "
                             "satisfy 0 <= lo < hi <= 1")
        nlo, nhi = (float(x) for x in self.noise_rel_bounds)
        if not 0.0 < nlo < nhi <= 10.0:
            raise ValueError(f"PhysicsPrior.noise_rel_bounds={self.noise_rel_bounds!r} must "
                             "satisfy 0 < lo < hi <= 10")
        sdl, sdh = (float(x) for x in self.heating_offset_sd_k)
        if not (np.isfinite(sdl) and np.isfinite(sdh) and sdl > 0 and sdh > 0):
            raise ValueError(f"PhysicsPrior.heating_offset_sd_k={self.heating_offset_sd_k!r} "
                             "must be two values in (0, inf) K (below, above the centre)")
        object.__setattr__(self, "heating_offset_sd_k", (sdl, sdh))
        olo, ohi = (float(x) for x in self.heating_offset_bounds_k)
        if not -30.0 <= olo < 0.0 < ohi <= 30.0:
            raise ValueError(f"PhysicsPrior.heating_offset_bounds_k={self.heating_offset_bounds_k!r}"
                             " must satisfy -30 <= lo < 0 < hi <= 30 (K)")
        object.__setattr__(self, "heating_offset_bounds_k", (olo, ohi))
        object.__setattr__(self, "efficiency_bounds", (lo, hi))
        object.__setattr__(self, "noise_rel_bounds", (nlo, nhi))

    def spec(self, name: str, nominal: float, eta_r_max: float, *,
             coastdown: bool = False) -> tuple:
        """``(kind, centre, sd, lo, hi)`` of one parameter's prior (natural units).

        ``kind`` is ``"normal"``, ``"lognormal"`` (``centre`` and ``sd`` of the
        log) or ``"splitnormal"`` (``sd`` a pair: below and above the centre),
        truncated to ``(lo, hi)``. ``coastdown``: the road load was measured
        (tighter ``C_dA``, ``C_r``).
        """
        if name in ("drag_area_m2", "rolling_resistance_coef", "aux_base_kw", "drive_loss_kw"):
            sd = {"drag_area_m2": self.drag_area_log_sd,
                  "rolling_resistance_coef": self.rolling_resistance_log_sd,
                  "aux_base_kw": self.aux_log_sd, "drive_loss_kw": self.aux_log_sd}[name]
            if coastdown and name != "aux_base_kw":
                sd = self.coastdown_log_sd
            if not nominal > 0:
                raise ValueError(f"{name}={nominal!r}: a lognormal prior needs a nominal value "
                                 "> 0; set it on the vehicle or leave the parameter out")
            return "lognormal", float(np.log(nominal)), sd, 0.0, np.inf
        if name in ("hvac_scale", "heating_scale", "cooling_scale"):
            return "lognormal", 0.0, self.hvac_log_sd, 0.0, np.inf
        if name == "warmup_scale":
            return "lognormal", 0.0, self.warmup_log_sd, 0.0, np.inf
        if name == "heating_offset_k":
            lo, hi = self.heating_offset_bounds_k
            return "splitnormal", nominal, self.heating_offset_sd_k, nominal + lo, nominal + hi
        if name == "linear_drag_n_per_mps":
            return "normal", nominal, self.linear_drag_sd_n_per_mps, 0.0, np.inf
        if name == "drivetrain_efficiency":
            lo, hi = self.efficiency_bounds
            if not lo < nominal < hi:
                raise ValueError(f"drivetrain_efficiency={nominal!r} is outside the prior "
                                 f"support ({lo}, {hi})")
            return "normal", nominal, self.efficiency_sd, lo, hi
        if name == "regen_scale":
            return "normal", 1.0, self.regen_scale_sd, 0.0, 1.0 / eta_r_max
        raise ValueError(f"params has unknown parameter {name!r}; allowed: {list(STAT_PARAMS)}")

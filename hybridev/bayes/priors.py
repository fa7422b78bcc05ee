"""Priors of the physics calibration: which parameters are sampled and their prior laws.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybridev.physics.stats import STAT_PARAMS

__all__ = ["DEFAULT_PARAMS", "PhysicsPrior"]


DEFAULT_PARAMS = ("drag_area_m2", "rolling_resistance_coef", "drivetrain_efficiency",
                  "aux_base_kw", "regen_scale")


@dataclass(frozen=True)
class PhysicsPrior:
    """Prior of the calibrated physics parameters, centred on the nominal vehicle.

    Widths are the project's choice (stated here; change them with
    :func:`dataclasses.replace`): coast-down and data-sheet values of
    ``C_dA`` and ``C_r`` are rarely more than 20-30 % off for a real car
    (tyres, load, wind), efficiency is known to a few points, auxiliary
    load only to a factor of ~1.6.

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
        ``log P_b ~ N(log nominal, sd)``; needs a nominal ``P_b > 0``.
    hvac_log_sd : float
        ``log hvac_scale ~ N(0, sd)``; the scale multiplies all four HVAC bands.
    regen_scale_sd : float
        ``s ~ N(1, sd)`` truncated to ``(0, 1 / max eta_r)`` so that no
        profile regenerates more than the braking energy.
    noise_rel_bounds : tuple of 2 float
        ``sigma_rel`` log-uniform on this range (scale-free).

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
    hvac_log_sd: float = 0.5
    regen_scale_sd: float = 0.2
    noise_rel_bounds: tuple[float, float] = (1e-3, 0.5)
    source: str = field(default="hybridev defaults (see class docstring)", compare=False)

    def __post_init__(self) -> None:
        for name in ("drag_area_log_sd", "rolling_resistance_log_sd", "linear_drag_sd_n_per_mps",
                     "efficiency_sd", "aux_log_sd", "hvac_log_sd", "regen_scale_sd"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"PhysicsPrior.{name}={v!r} is outside the allowed range "
                                 "(0, inf)")
        lo, hi = (float(x) for x in self.efficiency_bounds)
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"PhysicsPrior.efficiency_bounds={self.efficiency_bounds!r} must "
                             "satisfy 0 <= lo < hi <= 1")
        nlo, nhi = (float(x) for x in self.noise_rel_bounds)
        if not 0.0 < nlo < nhi <= 10.0:
            raise ValueError(f"PhysicsPrior.noise_rel_bounds={self.noise_rel_bounds!r} must "
                             "satisfy 0 < lo < hi <= 10")
        object.__setattr__(self, "efficiency_bounds", (lo, hi))
        object.__setattr__(self, "noise_rel_bounds", (nlo, nhi))

    def spec(self, name: str, nominal: float, eta_r_max: float) -> tuple:
        """``(kind, centre, sd, lo, hi)`` of one parameter's prior (natural units)."""
        if name in ("drag_area_m2", "rolling_resistance_coef", "aux_base_kw"):
            sd = {"drag_area_m2": self.drag_area_log_sd,
                  "rolling_resistance_coef": self.rolling_resistance_log_sd,
                  "aux_base_kw": self.aux_log_sd}[name]
            if not nominal > 0:
                raise ValueError(f"{name}={nominal!r}: a lognormal prior needs a nominal value "
                                 "> 0; set it on the vehicle or leave the parameter out")
            return "lognormal", float(np.log(nominal)), sd, 0.0, np.inf
        if name == "hvac_scale":
            return "lognormal", 0.0, self.hvac_log_sd, 0.0, np.inf
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

"""Ascidian oocyte (paper Fig. 1a, Video 1): a strong contraction wave from the pole of a sphere."""

import math
from dataclasses import dataclass

from wavewarp.coupled import COUPLINGS
from wavewarp.measurements import oocyte_measurements
from wavewarp.parameters import param
from wavewarp.quasistatic import SphereParameters, sphere_wave_run

NAME = "ascidian"
DESCRIPTION = "ascidian oocyte: telegraph wave from the pole, AC = 1.5, AI = 1.6, h/R = 0.05, μV = 24 Yh/R⁴ (Fig. 1a)"
# t_end 0: this fraction of the pole-to-pole time, the front ~130° from the pole. Focusing on the antipode, the
# conserved chemical contracts the shell past the fold (area 1/e, ~160° from the pole) from 0.69 of it on.
END_FRACTION = 0.65


@dataclass(frozen=True)
class Parameters(SphereParameters):
    AC: float = param(1.5, "metric coupling AC (the paper's)")
    AI: float = param(1.6, "curvature coupling AI (the paper's)")
    mu_v: float = param(24.0, "volume penalty μV in units of Y h / R⁴ (the paper's)", minimum=0.0)
    t_end: float = param(
        0.0, "end time; auto (0) = 0.65 π R / γ, before the wave focuses on the antipode", minimum=0.0, auto=True
    )
    coupling: str = param("overdamped", "overdamped or quasi-static (docs/studies/2026-12-02-readings-of-the-model.md)",
                          choices=COUPLINGS, legacy="quasi-static")


QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3


def measure(run) -> dict:
    """The oocyte measurements, the front speed fitted from 45° to 120° from the pole (the run ends before its
    front crosses 135°; nearer the pole the arrivals are the pulse's spread, not a travelling front)."""
    return oocyte_measurements(run, theta_range=(math.pi / 4, 2 * math.pi / 3))


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report, end_fraction=END_FRACTION,
                           measure=measure)

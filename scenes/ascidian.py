"""Ascidian oocyte (paper Fig. 1a, Video 1; SPEC §6): a contraction wave from the pole of a sphere."""

from wavewarp.scene import SPHERE_PARAMETERS, Param, sphere_wave_run

NAME = "ascidian"
DESCRIPTION = "ascidian oocyte: telegraph wave from the pole, AC = 1.5, AI = 1.6, h/R = 0.05, μV = 24 Yh/R⁴ (Fig. 1a)"
PARAMETERS = {
    **SPHERE_PARAMETERS,
    "AC": Param(1.5, "metric coupling (SPEC §6)"),
    "AI": Param(1.6, "curvature coupling (SPEC §6)"),
    "mu_v": Param(24.0, "volume penalty μV in units of Y h / R⁴ (SPEC §6)", minimum=0.0),
}
QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3, coarser than the default


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report)

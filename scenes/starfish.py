"""Starfish oocyte (paper Fig. 1b, Video 2; SPEC §6): a weaker contraction wave from the pole."""

from wavewarp.scene import SPHERE_PARAMETERS, Param, sphere_wave_run

NAME = "starfish"
DESCRIPTION = "starfish oocyte: telegraph wave from the pole, AC = 0.5, AI = 0.5, h/R = 0.05, μV = 24 Yh/R⁴ (Fig. 1b)"
PARAMETERS = {
    **SPHERE_PARAMETERS,
    "AC": Param(0.5, "metric coupling (SPEC §6)"),
    "AI": Param(0.5, "curvature coupling (SPEC §6)"),
    "mu_v": Param(24.0, "volume penalty μV in units of Y h / R⁴ (SPEC §6)", minimum=0.0),
}
QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3, coarser than the default


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report)

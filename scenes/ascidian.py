"""Ascidian oocyte (paper Fig. 1a, Video 1; SPEC §6): a contraction wave from the pole of a sphere."""

from wavewarp.scene import SPHERE_PARAMETERS, Param, sphere_wave_run

NAME = "ascidian"
DESCRIPTION = "ascidian oocyte: telegraph wave from the pole, AC = 1.5, AI = 1.6, h/R = 0.05, μV = 24 Yh/R⁴ (Fig. 1a)"
PARAMETERS = {
    **SPHERE_PARAMETERS,
    "AC": Param(1.5, "metric coupling (SPEC §6)"),
    "AI": Param(1.6, "curvature coupling (SPEC §6)"),
    "mu_v": Param(24.0, "volume penalty μV in units of Y h / R⁴ (SPEC §6)", minimum=0.0),
    # the starfish's resolution; the early 4-fold wrinkle at 30° (t = 0.3–1.7) is the same at level 5
    "level": Param(4, "icosphere level: 5120 triangles, 2.3 control edges per pulse width (the early wrinkle's "
                   "mode and size match level 5's)", minimum=1),
    "t_end": Param(0.0, "end time; 0 = 0.73 π R / γ, the front ~160° from the pole: focusing on the antipode, the "
                   "conserved chemical contracts the shell past its last equilibrium there (docs/scenes.md)",
                   minimum=0.0),  # fmt: skip
}
END_FRACTION = 0.73  # of the pole-to-pole time: the last frames before the focus (area element 0.51 of rest at 0.73, 1/e at 0.76)
QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3, coarser than the default


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report, end_fraction=END_FRACTION)

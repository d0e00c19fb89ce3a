"""Ascidian oocyte (paper Fig. 1a, Video 1; SPEC §6): a contraction wave from the pole of a sphere."""

from wavewarp.scene import SPHERE_PARAMETERS, Param, sphere_wave_run

NAME = "ascidian"
DESCRIPTION = "ascidian oocyte: telegraph wave from the pole, AC = 1.5, AI = 1.6, h/R = 0.05, μV = 24 Yh/R⁴ (Fig. 1a)"
PARAMETERS = {
    **SPHERE_PARAMETERS,
    "AC": Param(1.5, "metric coupling (SPEC §6)"),
    "AI": Param(1.6, "curvature coupling (SPEC §6)"),
    "mu_v": Param(24.0, "volume penalty μV in units of Y h / R⁴ (SPEC §6)", minimum=0.0),
    # the wave alone would take level 3 (pulse shape 0.8%; BENCHMARKS.md "Accuracy"), but the contraction
    # reaches 65% of R, and level 3's shell differs from level 4's by 0.7–1.9% R over the pass
    "level": Param(4, "icosphere level: 5120 triangles, 8 control edges per pulse width; the shell's shape "
                   "needs it (level 3: 0.7–1.9% R off level 4)", minimum=1),
    # the paper's σ² = 2/R² fixes the width only in its unstated length unit; read with our R = 10 (√2, R/7)
    # the shell buckles at t ≈ 8 and goes lopsided, against Fig. 1a. R/2 is the narrowest width of our scan
    # (3.5–5.66) that keeps it axisymmetric until the wave converges on the antipode (docs/scenes.md)
    "width": Param(5.0, "pulse width σR in length units: R/2 at the default R, which keeps the shell "
                   "axisymmetric as in Fig. 1a (√2, the starfish's, buckles it at t ≈ 8)", positive=True),
}
QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3, coarser than the default


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report)

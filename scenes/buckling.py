"""Buckling (supplement Fig. S1a, Movie 8; SPEC §6): a curvature wave buckles a thin sphere into n-fold patterns."""

from wavewarp.scene import SPHERE_PARAMETERS, Param, buckling_measurements, buckling_png, sphere_wave_run, symmetry_number

NAME = "buckling"
DESCRIPTION = "buckling sphere, R/h = 20, AI = 11, AC = 0: telegraph wave from the pole, seeded noise (Fig. S1a)"
PARAMETERS = {
    **SPHERE_PARAMETERS,
    "AC": Param(0.0, "metric coupling (SPEC §6)"),
    "AI": Param(11.0, "curvature coupling (SPEC §6)"),
    "mu_v": Param(0.0, "volume penalty μV in units of Y h / R⁴ (SPEC §6: none)", minimum=0.0),
    "overdamped": Param(True, "buckling is an instability: near it a relaxation may not converge within its budget; "
                        "the paper's overdamped update lets the shell lag its reference there (counted in --json)"),
    "relax_iterations": Param(2000, "NCG iterations per relaxation (the overdamped budget)", minimum=1),
    "relax_method": Param("ncg", "ncg: the budget is the overdamped shell's lag, so no Newton finish (auto and "
                          "newton need self_contact=false)", choices=("auto", "ncg", "newton")),  # fmt: skip
    "adaptive_dt": Param(True, "where a sharpening fold lowers the wave's stability bound below dt, go on at 0.9 × "
                         "the bound (the leapfrog re-centred, relaxations at the same time interval) instead of "
                         "stopping; dt returns when the bound allows"),  # fmt: skip
    "self_contact": Param(True, "keep the layers apart where the everted cap meets the far side (ours; SPEC has none): "
                          "contact distance h, docs/shell.md \"Self-contact\""),  # fmt: skip
    "noise": Param(1e-4, "rest-shape imperfection / R: the tiny seeded perturbation that breaks the symmetry",
                   minimum=0.0),
}
QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3, coarser than the default


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report, profile=symmetry_number,
                           measure=buckling_measurements, figures={"symmetry": buckling_png})

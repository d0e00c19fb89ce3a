"""Buckling modes (supplement Fig. S1b, Movie 9; SPEC §5, §6): a steady tanh front; n grows with AI, falls with h/R."""

import math

from wavewarp.scene import SPHERE_PARAMETERS, Param, buckling_measurements, buckling_png, sphere_wave_run, symmetry_number

NAME = "buckling-modes"
DESCRIPTION = "buckling modes: steady tanh front on a sphere, AI 7.5–13.5, h/R 0.01–0.075 (Fig. S1b)"
PARAMETERS = {
    **SPHERE_PARAMETERS,
    "AC": Param(0.0, "metric coupling (SPEC §6)"),
    "AI": Param(10.5, "curvature coupling; Fig. S1b spans 7.5–13.5"),
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
    "noise": Param(1e-4, "rest-shape imperfection / R: breaks the symmetry so the n-fold mode can form",
                   minimum=0.0),
    "k": Param(1.0, "front steepness k (1/length): the front is ~2/k = 2 length units wide, as the oocyte pulse",
               positive=True),
    "delta": Param(0.0, "front height δ below the pole (length); 0 = R/2, between pole and equator", minimum=0.0),
    # SPEC §6, §7 (Fig. S1b): above the wave checks' level 3 (BENCHMARKS.md "Accuracy"), for the buckling wavelength
    "level": Param(4, "icosphere level: the buckling wavelength 2π√(Rh)/(12(1−ν²))^¼ = 7.8 at h/R = 0.05 (3.5 at "
                   "0.01) spans 10 (4.6) control edges; level 3 gives 5 (2.3)", minimum=1),
}
QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3, coarser than the default


def build(p, *, mesh=None, device=None, seed=0, report=print):
    delta = p["delta"] or 0.5 * p["radius"]
    initial = {"kind": "front", "k": p["k"], "delta": delta}
    run = sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, initial=initial, report=report,
                          profile=symmetry_number, measure=buckling_measurements, figures={"symmetry": buckling_png})
    run.front_start = p["radius"] * math.acos(max(-1.0, 1 - delta / p["radius"]))  # the front's arc from the pole
    return run

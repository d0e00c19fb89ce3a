"""Buckling (supplement Fig. S1a, Movie 8): a curvature wave buckles a thin sphere."""

from dataclasses import dataclass

from wavewarp.figures import buckling_png
from wavewarp.measurements import buckling_measurements, symmetry_number
from wavewarp.parameters import param
from wavewarp.quasistatic import SphereParameters, sphere_wave_run
from wavewarp.quasistatic_batch import sphere_wave_batch

NAME = "buckling"
DESCRIPTION = "buckling sphere, R/h = 20, AI = 11, AC = 0: telegraph wave from the pole, seeded noise (Fig. S1a)"


@dataclass(frozen=True)
class BucklingParameters(SphereParameters):
    """What the buckling scenes share: a shell that may lag its reference, self-contact, the
    adaptive chemistry step and a seeded imperfection."""

    AI: float = param(11.0, "curvature coupling AI (the paper's)")
    accept_unconverged: bool = param(True, "accept a relaxation that spends its budget: the shell lags its reference near the "
                             "instability")  # fmt: skip
    relax_iterations: int = param(2000, "CG iterations per relaxation (the lagging shell's budget)", minimum=1)
    relax_method: str = param("ncg", "ncg: CG only (auto and newton need self_contact=false)",
                              choices=("auto", "ncg", "newton"))  # fmt: skip
    adaptive_dt: bool = param(True, "where a sharpening fold lowers the wave's stability bound below dt, step on at "
                              "0.9 × the bound; dt returns when the bound allows")  # fmt: skip
    self_contact: bool = param(True, "keep the layers apart where the everted cap meets the far side")
    noise: float = param(1e-4, "rest-shape imperfection / R (seeded by --seed): breaks the symmetry", minimum=0.0)


@dataclass(frozen=True)
class Parameters(BucklingParameters):
    pass


QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, report=report, profile=symmetry_number,
                           measure=buckling_measurements, figures={"symmetry": buckling_png},
                           self_contact=p.self_contact, adaptive_dt=p.adaptive_dt)  # fmt: skip


def build_batch(ps, *, seeds, device=None, report=print):
    """Worlds of this scene stepped together (wavewarp/quasistatic_batch.py; adaptive_dt and self_contact
    false): one parameter set and seed per world."""
    return sphere_wave_batch(NAME, ps, seeds=seeds, device=device, report=report, profile=symmetry_number,
                             measure=buckling_measurements)  # fmt: skip

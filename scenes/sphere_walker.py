"""Sphere walker (paper Fig. 3a,b, Video 4): FHN waves make a sphere walk on the ground."""

from dataclasses import dataclass

from wavewarp.parameters import param
from wavewarp.batch import walker_batch
from wavewarp.walker import WalkerParameters, sphere_walker_recipe, sphere_walker_run

NAME = "sphere-walker"
DESCRIPTION = "sphere walker, R = 25, h = 0.084R: FHN waves from the equator, AC = 0.1, μV = 0.4 Yh/R⁴, on the ground (Fig. 3a)"


@dataclass(frozen=True)
class Parameters(WalkerParameters):
    radius: float = param(25.0, "sphere radius R (the paper's)", positive=True)
    AC: float = param(0.1, "metric coupling AC (the paper's)")
    mu_v: float = param(0.4, "volume penalty μV in units of Y h / R⁴ (the paper's)", minimum=0.0)
    level: int = param(4, "icosphere level (level 4: 5,120 triangles, where the FHN front travels)", minimum=1)


# --quick: a smoke test at level 2 (its front pins), the contact coupled by 2 sweeps
QUICK = {"level": 2, "periods": 2.2, "frames": 4, "contact_sweeps": 2}


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_walker_run(NAME, p, seed=seed, mesh=mesh, device=device, report=report)


recipe = sphere_walker_recipe  # the scene's noiseless mesh and options (its control points: shape gradients)


def build_batch(ps, *, seeds, device=None, report=print, mechanics_dt=None, rest_shapes=None):
    """Worlds of this scene stepped together (wavewarp/batch.py): one parameter set and seed per world;
    `mechanics_dt` the settling steps (`WalkerRun`'s; default: the strictest world's bounds);
    `rest_shapes(mesh)` one displacement of the control points per world (`walker_batch`'s)."""
    return walker_batch(NAME, recipe, ps, seeds=seeds, device=device, report=report,
                        mechanics_dt=mechanics_dt, rest_shapes=rest_shapes)

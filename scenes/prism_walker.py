"""Prism walker (paper Fig. 3a,d, Video 5): FHN waves from a vertex make a prism walk."""

import math
from dataclasses import dataclass

from wavewarp.mesh import prism
from wavewarp.parameters import param

from wavewarp.batch import walker_batch
from wavewarp.walker import WalkerParameters, box_walker_recipe, box_walker_run

NAME = "prism-walker"
DESCRIPTION = "prism walker, all edges 2.3R (R = 25), h = 0.084R: FHN waves from a vertex, AC = 0.2, μV = 11.1 Yh/L⁴ (Fig. 3a)"
L_OVER_R = 2.3  # all edges 2.3 R (the paper's); R is the speed's length unit
ORIGINS = {  # in units of L, the prism lying on a square face with its axis along x
    "vertex": (-0.5, 0.0, 1 / math.sqrt(3.0)),  # the top corner of the back cap (paper Fig. 3d)
    "face": (-0.5, 0.0, 0.0),  # the centre of the back cap
}


@dataclass(frozen=True)
class Parameters(WalkerParameters):
    edge: float = param(57.5, "L = 2.3 R with R = 25 (the paper's)", positive=True)
    AC: float = param(0.2, "metric coupling AC (the paper's)")
    mu_v: float = param(11.1, "volume penalty μV in units of Y h / L⁴ (the paper's)", minimum=0.0)
    divisions: int = param(34, "control squares per edge (even): 9,248 triangles, the sphere walker's level 4 "
                           "resolution", minimum=2, even=True)  # fmt: skip
    rule: str = param("3", "quadrature rule")
    origin: str = param("vertex", "where the first pulse starts", choices=tuple(ORIGINS))


# --quick: a smoke test at 4 divisions (its front pins), the contact coupled by 2 sweeps
QUICK = {"divisions": 4, "periods": 2.2, "frames": 4, "contact_sweeps": 2}


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return box_walker_run(NAME, p, prism, ORIGINS, seed=seed, radius=p.edge / L_OVER_R, axis_to_x=True, mesh=mesh,
                          device=device, report=report)  # fmt: skip


def recipe(p, *, device=None, report=print):
    """The scene's noiseless mesh (its control points: shape gradients) and `WalkerBatch` options."""
    return box_walker_recipe(p, prism, ORIGINS, radius=p.edge / L_OVER_R, axis_to_x=True, device=device, report=report)


def build_batch(ps, *, seeds, device=None, report=print, mechanics_dt=None, rest_shapes=None):
    """Worlds of this scene stepped together (wavewarp/batch.py): one parameter set and seed per world;
    `mechanics_dt` the settling steps (`WalkerRun`'s; default: the strictest world's bounds);
    `rest_shapes(mesh)` one displacement of the control points per world (`walker_batch`'s)."""
    return walker_batch(NAME, recipe, ps, seeds=seeds, device=device, report=report,
                        mechanics_dt=mechanics_dt, rest_shapes=rest_shapes)

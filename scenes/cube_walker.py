"""Cube walker (Video 7): FHN waves from a top edge make a cube walk."""

from dataclasses import dataclass

from wavewarp.mesh import cube
from wavewarp.parameters import param

from wavewarp.batch import walker_batch
from wavewarp.walker import WalkerParameters, box_walker_recipe, box_walker_run

NAME = "cube-walker"
DESCRIPTION = "cube walker, edge 2R (R = 25), h = 0.084R: FHN waves from a top edge, AC = 0.2, μV = 6.4 Yh/L⁴ (Video 7)"
L_OVER_R = 2.0  # the edge in units of R (the speed's length unit): 2R, the sphere walker's height
ORIGINS = {  # in units of L, the cube resting on a face
    "edge": (-0.5, 0.0, 0.5),  # the midpoint of the back top edge
    "face": (-0.5, 0.0, 0.0),  # the centre of the back face
}


@dataclass(frozen=True)
class Parameters(WalkerParameters):
    edge: float = param(50.0, "L = 2R, the sphere walker's height", positive=True)
    AC: float = param(0.2, "metric coupling AC (as the prism walker)")
    mu_v: float = param(6.4, "volume penalty μV in units of Y h / L⁴ (0.4 Y h / R⁴ with R = L/2)", minimum=0.0)
    divisions: int = param(32, "control squares per face edge (even): 12,288 triangles, the sphere walker's level 4 "
                           "resolution", minimum=2, even=True)  # fmt: skip
    rule: str = param("3", "quadrature rule")
    origin: str = param("edge", "where the first pulse starts", choices=tuple(ORIGINS))


# --quick: a smoke test at 4 divisions (its front pins), the contact coupled by 2 sweeps
QUICK = {"divisions": 4, "periods": 2.2, "frames": 4, "contact_sweeps": 2}


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return box_walker_run(NAME, p, cube, ORIGINS, radius=p.edge / L_OVER_R, mesh=mesh, device=device, seed=seed,
                          report=report)  # fmt: skip


def recipe(p, *, device=None, report=print):
    """The scene's noiseless mesh (its control points: shape gradients) and `WalkerBatch` options."""
    return box_walker_recipe(p, cube, ORIGINS, radius=p.edge / L_OVER_R, device=device, report=report)


def build_batch(ps, *, seeds, device=None, report=print, mechanics_dt=None, rest_shapes=None):
    """Worlds of this scene stepped together (wavewarp/batch.py): one parameter set and seed per world;
    `mechanics_dt` the settling steps (`WalkerRun`'s; default: the strictest world's bounds);
    `rest_shapes(mesh)` one displacement of the control points per world (`walker_batch`'s)."""
    return walker_batch(NAME, recipe, ps, seeds=seeds, device=device, report=report,
                        mechanics_dt=mechanics_dt, rest_shapes=rest_shapes)

"""Cube walker (Video 7; SPEC §6): FHN waves from a top edge make a cube walk."""

from wavewarp.mesh import cube
from wavewarp.scene import Param
from wavewarp.walker import box_walker_run, walker_parameters

NAME = "cube-walker"
DESCRIPTION = "cube walker, edge 2R (R = 25), h = 0.084R: FHN waves from a top edge, AC = 0.2, μV = 6.4 Yh/L⁴ (Video 7)"
L_OVER_R = 2.0  # the edge in units of R (the speed's length unit): 2R, the sphere walker's height
ORIGINS = {  # in units of L, the cube resting on a face
    "edge": (-0.5, 0.0, 0.5),  # the midpoint of the back top edge
    "face": (-0.5, 0.0, 0.0),  # the centre of the back face
}
PARAMETERS = walker_parameters(
    edge=Param(50.0, "L (ours): 2R, the sphere walker's height", positive=True),
    thickness=Param(2.1, "h = 0.084 R, as the other walkers", positive=True),
    AC=Param(0.2, "metric coupling (ours: the prism walker's)"),
    AI=Param(0.0, "curvature coupling (SPEC §6)"),
    mu_v=Param(6.4, "volume penalty μV in units of Y h / L⁴ (ours: 0.4 Y h / R⁴ with R = L/2, as the other walkers)",
               minimum=0.0),  # fmt: skip
    # SPEC §6; BENCHMARKS.md "Accuracy": the level-4 FHN front with two mass corrections, 10.5% slow
    divisions=Param(32, "control squares per face edge (even): 12,288 triangles, mean control edge 0.071 R, the "
                    "sphere walker's level 4 resolution (benchmarks/accuracy.py equivalent_level)", minimum=2),
    rule=Param("3", "quadrature: the 3-point rule (as the prism walker)"),
    origin=Param("edge", "where the first pulse starts", choices=tuple(ORIGINS)),
)
QUICK = {"divisions": 4, "periods": 2.2, "frames": 4}  # --quick: coarser smoke test, 4 divisions (192 triangles; front pins)


def build(p, *, mesh=None, device=None, seed=0, report=print):
    del seed  # deterministic
    return box_walker_run(NAME, p, cube, ORIGINS, radius=p["edge"] / L_OVER_R, mesh=mesh, device=device, report=report)

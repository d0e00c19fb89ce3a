"""Prism walker (paper Fig. 3a,d, Video 5; SPEC §6): FHN waves from a vertex make a prism walk."""

import math

from wavewarp.mesh import prism
from wavewarp.scene import Param
from wavewarp.walker import box_walker_run, walker_parameters

NAME = "prism-walker"
DESCRIPTION = "prism walker, all edges 2.3R (R = 25), h = 0.084R: FHN waves from a vertex, AC = 0.2, μV = 11.1 Yh/L⁴ (Fig. 3a)"
L_OVER_R = 2.3  # all edges 2.3 R (SPEC §6); R is the speed's length unit
ORIGINS = {  # in units of L, the prism lying on a square face with its axis along x
    "vertex": (-0.5, 0.0, 1 / math.sqrt(3.0)),  # the top corner of the back cap (paper Fig. 3d)
    "face": (-0.5, 0.0, 0.0),  # the centre of the back cap
}
PARAMETERS = walker_parameters(
    edge=Param(57.5, "L = 2.3 R, R = 25 (SPEC §6)", positive=True),
    thickness=Param(2.1, "h = 0.084 R (SPEC §6)", positive=True),
    AC=Param(0.2, "metric coupling (SPEC §6)"),
    AI=Param(0.0, "curvature coupling (SPEC §6)"),
    mu_v=Param(11.1, "volume penalty μV in units of Y h / L⁴ (SPEC §6)", minimum=0.0),
    # SPEC §6; BENCHMARKS.md "Accuracy": the level-4 FHN front with two mass corrections, 10.5% slow
    divisions=Param(34, "control squares per edge (even): 9,248 triangles, mean control edge 0.075 R, the sphere "
                    "walker's level 4 resolution (benchmarks/accuracy.py equivalent_level)", minimum=2),
    rule=Param("3", "quadrature: the 3-point rule (the wave guides' '3x4' resolves the rounded edges' "
               "curvature better at 4× the cost; docs/walkers.md)"),  # fmt: skip
    origin=Param("vertex", "where the first pulse starts", choices=tuple(ORIGINS)),
)
QUICK = {"divisions": 4, "periods": 2.2, "frames": 4}  # --quick: coarser smoke test, 4 divisions (128 triangles; front pins)


def build(p, *, mesh=None, device=None, seed=0, report=print):
    del seed  # deterministic
    return box_walker_run(NAME, p, prism, ORIGINS, radius=p["edge"] / L_OVER_R, axis_to_x=True, mesh=mesh,
                          device=device, report=report)  # fmt: skip

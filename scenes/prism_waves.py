"""Prism wave guide (paper Fig. 2): the face opposite the origin shows a 3- or 5-fold imprint."""

import math
from dataclasses import dataclass

from wavewarp.mesh import prism
from wavewarp.parameters import param
from wavewarp.quasistatic import BoxParameters, box_wave_run
from wavewarp.unfolding import prism_faces, prism_fronts

NAME = "prism-waves"
DESCRIPTION = "triangular prism wave guide, L = 20h: telegraph wave from the triangle-face centre, an edge or a vertex (Fig. 2)"
_R = 1 / math.sqrt(3.0)  # circumradius of the unit triangle
ORIGINS = {  # in units of L; the triangular caps lie at z = ±L/2, one corner towards +y
    "face": (0.0, 0.0, 0.5),
    "edge": (0.0, -0.5 * _R, 0.5),  # midpoint of the cap edge opposite the +y corner
    "vertex": (0.0, _R, 0.5),
}


@dataclass(frozen=True)
class Parameters(BoxParameters):
    origin: str = param("face", "where the pulse starts", choices=tuple(ORIGINS))


QUICK = {"divisions": 4, "frames": 3, "t_end": 4.0, "rule": "3"}  # --quick: a smoke test, 4 divisions


def build(p, *, mesh=None, device=None, seed=0, report=print):
    del seed  # the box scenes are deterministic
    return box_wave_run(NAME, p, prism, ORIGINS, faces=prism_faces, fronts=prism_fronts, mesh=mesh, device=device,
                        report=report)  # fmt: skip

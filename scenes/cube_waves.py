"""Cube wave guide (paper Fig. 2): a point wave on a cube loses its radial symmetry."""

from dataclasses import dataclass

from wavewarp.mesh import cube
from wavewarp.parameters import param
from wavewarp.quasistatic import BoxParameters, box_wave_run

NAME = "cube-waves"
DESCRIPTION = "cube wave guide, L = 20h: telegraph wave from a face centre, an edge or a vertex, AC = 0.2 (Fig. 2)"
ORIGINS = {"face": (0.0, 0.0, 0.5), "edge": (0.5, 0.0, 0.5), "vertex": (0.5, 0.5, 0.5)}  # in units of L


@dataclass(frozen=True)
class Parameters(BoxParameters):
    origin: str = param("face", "where the pulse starts", choices=tuple(ORIGINS))


QUICK = {"divisions": 4, "frames": 3, "t_end": 4.0, "rule": "3"}  # --quick: a smoke test, 4 divisions


def build(p, *, mesh=None, device=None, seed=0, report=print):
    del seed  # the box scenes are deterministic
    return box_wave_run(NAME, p, cube, ORIGINS, mesh=mesh, device=device, report=report)

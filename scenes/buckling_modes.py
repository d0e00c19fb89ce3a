"""Buckling modes (supplement Fig. S1b, Movie 9): a steady tanh front; n grows with AI, falls with h/R."""

import math
from dataclasses import dataclass

from wavewarp.figures import buckling_png
from wavewarp.measurements import buckling_measurements, symmetry_number
from wavewarp.parameters import param
from wavewarp.quasistatic import sphere_wave_run
from wavewarp.quasistatic_batch import sphere_wave_batch
from wavewarp.scenes.buckling import BucklingParameters

NAME = "buckling-modes"
DESCRIPTION = "buckling modes: steady tanh front on a sphere, AI 7.5–13.5, h/R 0.01–0.075 (Fig. S1b)"


@dataclass(frozen=True)
class Parameters(BucklingParameters):
    AI: float = param(10.5, "curvature coupling AI (Fig. S1b spans 7.5–13.5)")
    k: float = param(1.0, "front steepness k (1/length): the front is ~2/k wide", positive=True)
    delta: float = param(0.0, "front height δ below the pole (length); auto (0) = R/2", minimum=0.0, auto=True)


QUICK = {"level": 3, "frames": 4, "t_end": 4.0}  # --quick: a smoke test at level 3


def front(p) -> tuple:
    """The steady front's initial values and its arc from the pole at t = 0."""
    delta = p.delta or 0.5 * p.radius
    return {"kind": "front", "k": p.k, "delta": delta}, p.radius * math.acos(max(-1.0, 1 - delta / p.radius))


def build(p, *, mesh=None, device=None, seed=0, report=print):
    initial, front_start = front(p)
    run = sphere_wave_run(NAME, p, mesh=mesh, device=device, seed=seed, initial=initial, report=report,
                          profile=symmetry_number, measure=buckling_measurements, figures={"symmetry": buckling_png},
                          self_contact=p.self_contact, adaptive_dt=p.adaptive_dt)  # fmt: skip
    run.front_start = front_start
    return run


def build_batch(ps, *, seeds, device=None, report=print):
    """Worlds of this scene stepped together (wavewarp/quasistatic_batch.py; adaptive_dt and self_contact
    false): one parameter set and seed per world (the Fig. S1b sweep over AI and thickness)."""
    initial, front_start = front(ps[0])
    return sphere_wave_batch(NAME, ps, seeds=seeds, initial=initial, front_start=front_start, device=device,
                             report=report, profile=symmetry_number, measure=buckling_measurements)  # fmt: skip

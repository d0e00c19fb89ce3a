"""Bilayer walker (supplement Movie 10): the sphere walker actuated through the bilayer model."""

from functools import partial

from wavewarp.batch import walker_batch
from wavewarp.walker import sphere_walker_recipe, sphere_walker_run

from wavewarp.scenes.sphere_walker import QUICK, Parameters  # noqa: F401 — the same sphere, coupling and chemistry

NAME = "bilayer-walker"
DESCRIPTION = "bilayer walker: the sphere walker with the bilayer shell model (ā = Λ² ā⁰, b̄ = Λ b̄⁰ - A c ā⁰; Movie 10)"


def build(p, *, mesh=None, device=None, seed=0, report=print):
    return sphere_walker_run(NAME, p, seed=seed, mesh=mesh, device=device, bilayer=True, report=report)


recipe = partial(sphere_walker_recipe, bilayer=True)  # the scene's noiseless mesh and options


def build_batch(ps, *, seeds, device=None, report=print, mechanics_dt=None, rest_shapes=None):
    """Worlds of this scene stepped together (wavewarp/batch.py): one parameter set and seed per world;
    `mechanics_dt` the settling steps (`WalkerRun`'s; default: the strictest world's bounds);
    `rest_shapes(mesh)` one displacement of the control points per world (`walker_batch`'s)."""
    return walker_batch(NAME, recipe, ps, seeds=seeds, device=device, report=report,
                        mechanics_dt=mechanics_dt, rest_shapes=rest_shapes)

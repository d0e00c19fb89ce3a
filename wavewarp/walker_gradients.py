"""Walker gradients by central differences over the worlds of one batch (docs/theory/gradients.md, "Walkers").

The objective is the walk itself: the centre of mass's displacement along the wave's direction, in R,
at every chemistry step of the run (its value at the end is J). For each parameter θ and step δ the
batch holds the worlds θ ± δ beside the unperturbed one; they share every chemistry and mechanics
step (the strictest world's), so (J(θ+δ) - J(θ-δ)) / 2δ is the derivative of one discretisation.
The run is in float64. Two steps per parameter measure whether the derivative has converged (their
relative `agreement`), which is what fails past the horizon of a chaotic gait. The wave may depend on
the shape (sensitive walkers): the differences go through the whole coupled run. The ground's and the
drag's parameters are one per batch: their ± worlds run as batches of one world each, with the main
batch's steps.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .gradients import GradientError, control_points, control_scale
from .measurements import locomotion
from .parameters import SceneError, fields, parse

PER_WORLD = ("AC", "AI", "thickness", "young", "mu_v", "elongation")  # the batch's per-world shell and shape parameters
SHARED = ("friction", "sharpness", "stiffness", "contact_damping", "drag")  # one ground and drag per batch
PARAMETERS = PER_WORLD + SHARED
OBJECTIVES = ("distance", "speed")  # R along the wave at the end; R per measured period between the first and last pulse
STEPS = (1e-4, 1e-5)  # relative steps of the central differences (absolute where θ = 0)
AGREEMENT = 1e-3  # two steps' relative disagreement beyond which a derivative is not resolved


class WalkerGradientError(GradientError):
    """A walker gradient that cannot be taken as asked (the message names the fix)."""


def check_walker_differentiable(wrt, objective: str = "distance", steps=STEPS, points=()) -> None:
    """Raise WalkerGradientError, naming the fix, where `walker_gradient` cannot be taken."""
    unknown = [name for name in wrt if name not in PARAMETERS]
    if unknown or not (len(wrt) or len(points)):
        raise WalkerGradientError(f"--wrt {','.join(unknown) or '(nothing)'}: a walker's differentiable parameters are "
                                  f"{', '.join(PARAMETERS)}, and its rest shape's control points (--points)")  # fmt: skip
    if objective not in OBJECTIVES:
        raise WalkerGradientError(f"--objective {objective}: a walker's objectives are {', '.join(OBJECTIVES)}")
    if len(steps) < 1 or any(not 0.0 < step < 0.5 for step in steps):
        raise WalkerGradientError(f"steps {list(steps)}: give one or more relative steps between 0 and 0.5, e.g. 1e-3,1e-4")


def check_walker_values(p, wrt, steps=STEPS) -> None:
    """Raise WalkerGradientError, naming the fix, where a parameter's value leaves no central difference: Coulomb's
    k_f = inf, an automatic 0, or θ - δ outside the parameter's valid range (the scene parameters' own check)."""
    known = fields(p)
    for name in wrt:
        theta = float(getattr(p, name))
        if name == "sharpness" and math.isinf(theta):
            raise WalkerGradientError("sharpness = inf is Coulomb's law, which has no derivative in k_f: --set "
                                      "sharpness=1e4 walks as Coulomb does (docs/studies/2026-11-27-walker-regime-scans.md)")  # fmt: skip
        if known[name].metadata.get("auto") and theta == 0:
            raise WalkerGradientError(f"{name} = 0 means automatic: give it a value (--set {name}=...)")
        lowest = theta - max(steps) * (abs(theta) or 1.0)
        try:
            parse(known[name], repr(lowest))
        except SceneError as error:
            raise WalkerGradientError(f"{name} = {theta:g}: the central difference's θ - δ leaves its valid range "
                                      f"({error}); differentiate further inside it") from None  # fmt: skip


def perturbed_worlds(p, wrt, steps) -> list:
    """[(name, δ, sign, parameters)]: the unperturbed world first (name None), then θ ± δ for each parameter
    and step (δ = step × |θ|, or step where θ = 0)."""
    worlds = [(None, 0.0, 0, p)]
    for name in wrt:
        theta = float(getattr(p, name))
        for step in steps:
            delta = step * abs(theta) if theta else step
            worlds += [(name, delta, sign, replace(p, **{name: theta + sign * delta})) for sign in (1, -1)]
    return worlds


def forward_distance(trace: np.ndarray, forward, radius: float) -> np.ndarray:
    """The centre of mass's displacement along `forward` since the trace's first row, in R, at every row
    (rows: t, c at the origin, centre of mass, origin vertex)."""
    com = trace[:, 2:5]
    return (com - com[0]) @ np.asarray(forward, dtype=np.float64) / radius


def walker_gradient(scene, p, wrt=(), *, points=(), rest_shape=None, objective: str = "distance", steps=STEPS,
                    seed: int = 0, max_worlds=None, device=None, report=print) -> dict:  # fmt: skip
    """dJ/dθ of a walker `scene` (a scene module: its `build_batch(ps, seeds=, device=, report=, mechanics_dt=,
    rest_shapes=)` and `recipe(p)`) at parameters `p` for the parameters named in `wrt`, by central differences over
    one float64 batch (PER_WORLD), and over batches of one world stepped as that batch (SHARED); and dJ/dX of the rest
    shape's control points `points` (vertex indices of the scene's mesh, or "all"), each coordinate's ± worlds in
    the main batch (δ = step × the control points' RMS distance from their centroid). `rest_shape`: a (V, 3)
    displacement of the scene's control points that every world starts from (None: the scene's shape).
    `max_worlds`: at most that many worlds a batch (device memory); the worlds past the first batch run in
    further batches given its chemistry and mechanics steps, as the shared parameters' do.

    Returns {"objective": J (`objective`: the distance at the end, or the speed), "gradient": {name: dJ/dθ with the
    smallest step}, "agreement": {name: |g(δ₁) - g(δ_k)| / |g(δ_k)|, the largest step against the smallest},
    "steps", "deltas": {name: [δ...]}, "times": chemistry times, "distance": the distance D(t) of the
    unperturbed world, "derivatives": {name: [dD/dθ(t) per step]}, "period": the unperturbed world's measured period
    (None if fewer than two pulses), "period_kinetic": the FHN kinetics' period, "settle_dt": the mechanics steps the
    worlds settled and walk with (`WalkerRun`'s `mechanics_dt`)}; with `points`, also "points" (the indices),
    "rest_vertices" (the control points the gradient is taken at, V × 3), "shape_gradient" (dJ/dX, P × 3
    NumPy, per unit length), "shape_agreement" (‖g(δ₁) - g(δ_k)‖ / ‖g(δ_k)‖), "shape_deltas" ([δ...], lengths)
    and "shape_derivatives" (dD/dX(t): steps × P × 3 × times)."""
    check_walker_differentiable(wrt, objective, steps, points)
    check_walker_values(p, wrt, steps)
    p = replace(p, dtype="float64")
    worlds = perturbed_worlds(p, [name for name in wrt if name in PER_WORLD], steps)
    rest = scene.recipe(p, device=device, report=lambda message: None)[0].vertices
    points = control_points(points, len(rest))
    base = np.zeros_like(rest) if rest_shape is None else np.asarray(rest_shape, dtype=np.float64)
    if base.shape != rest.shape:
        raise WalkerGradientError(f"rest_shape: a {rest.shape} displacement of the scene's control points, not "
                                  f"{base.shape}")  # fmt: skip
    rest = rest + base
    scale = control_scale(rest)
    moved, displacements = shape_worlds(p, points, steps, base, scale)
    worlds, displacements = worlds + moved, [base] * len(worlds) + displacements
    shaped = points or rest_shape is not None
    size = len(worlds) if max_worlds is None else int(max_worlds)
    if size < 1:
        raise WalkerGradientError(f"max_worlds {max_worlds}: give at least 1 world a batch")
    batch = scene.build_batch([q for *_, q in worlds[:size]], seeds=[seed] * min(size, len(worlds)), device=device,
                              report=report, rest_shapes=(lambda mesh: displacements[:size]) if shaped else None)  # fmt: skip
    forward, radius = batch.placed[0].forward, batch.radius
    traces = list(finished(batch, worlds[:size]))

    def stepped_as_first(entries, shapes) -> list:  # the traces of `entries` run as one more batch, given its steps
        more = scene.build_batch([replace(q, dt=batch.wave.dt) for *_, q in entries], seeds=[seed] * len(entries),
                                 device=device, report=report, mechanics_dt=batch.settle_dt,
                                 rest_shapes=(lambda mesh: shapes) if shaped else None)  # fmt: skip
        return finished(more, entries)

    for start in range(size, len(worlds), size):  # the rest of the batch's worlds
        traces += stepped_as_first(worlds[start:start + size], displacements[start:start + size])
    for entry in perturbed_worlds(p, [name for name in wrt if name in SHARED], steps)[1:]:  # one ground a batch
        traces += stepped_as_first([entry], [base])
        worlds.append(entry)
    distances = [forward_distance(trace, forward, radius) for trace in traces]
    ends = [objective_value(objective, trace, distance, forward, radius, batch.period_kinetic)
            for trace, distance in zip(traces, distances)]  # fmt: skip
    derivatives, deltas, differences = {}, {}, {}
    for w in range(1, len(worlds), 2):
        key, delta, _, _ = worlds[w]
        derivatives.setdefault(key, []).append((distances[w] - distances[w + 1]) / (2.0 * delta))
        differences.setdefault(key, []).append((ends[w] - ends[w + 1]) / (2.0 * delta))
        deltas.setdefault(key, []).append(delta)
    result = {"objective": float(ends[0]), "gradient": {name: float(differences[name][-1]) for name in wrt},
              "agreement": {name: relative_disagreement(differences[name]) for name in wrt}, "steps": list(steps),
              "deltas": {name: deltas[name] for name in wrt}, "times": batch.traces[0][:, 0], "distance": distances[0],
              "derivatives": {name: derivatives[name] for name in wrt},
              "period": batch.measurements(0, batch.time)["period"], "period_kinetic": batch.period_kinetic,
              "settle_dt": batch.settle_dt}  # fmt: skip
    if points:
        keys = [("shape", point, axis) for point in points for axis in range(3)]
        by_step = np.array([[differences[key][k] for key in keys] for k in range(len(steps))])  # steps × 3P
        series = np.array([[derivatives[key][k] for key in keys] for k in range(len(steps))])
        result.update(points=points, rest_vertices=rest, shape_gradient=by_step[-1].reshape(len(points), 3),
                      shape_agreement=relative_disagreement(list(by_step)), shape_deltas=[step * scale for step in steps],
                      shape_derivatives=series.reshape(len(steps), len(points), 3, -1))  # fmt: skip
    return result


def shape_worlds(p, points, steps, base: np.ndarray, scale: float) -> tuple:
    """([(("shape", point, axis), δ, sign, p)], [rest displacement]) for each control coordinate, step and sign:
    `base` with that coordinate moved by sign × δ, δ = step × `scale`."""
    worlds, displacements = [], []
    for point in points:
        for axis in range(3):
            for step in steps:
                for sign in (1, -1):
                    worlds.append((("shape", point, axis), step * scale, sign, p))
                    displacements.append(base.copy())
                    displacements[-1][point, axis] += sign * step * scale
    return worlds, displacements


def relative_disagreement(values) -> float:
    """‖g(δ₁) - g(δ_k)‖ / ‖g(δ_k)‖ of one derivative (or gradient vector) per step."""
    first, last = np.asarray(values[0], dtype=np.float64), np.asarray(values[-1], dtype=np.float64)
    return float(np.linalg.norm(first - last) / max(float(np.linalg.norm(last)), 1e-300))


def objective_value(objective: str, trace: np.ndarray, distance: np.ndarray, forward, radius: float,
                    period_kinetic: float) -> float:  # fmt: skip
    """A world's objective: its `distance` at the end, or its speed (R per measured period, `locomotion`'s)."""
    if objective == "distance":
        return float(distance[-1])
    speed = locomotion(trace, forward, radius, 0.0, period_kinetic)["speed_R_per_T"]
    if speed is None:
        raise WalkerGradientError("the speed is measured between the first and the last pulse, and this run has fewer "
                                  "than two: --set periods=2 or more, or --objective distance")  # fmt: skip
    return float(speed)


def finished(batch, worlds) -> list:
    """Run `batch` (its worlds described by `worlds`, as `perturbed_worlds` gives them); every world's trace, or
    WalkerGradientError where one stopped."""
    for w, result in enumerate(batch.run()):
        if result["status"] != "done":
            raise WalkerGradientError(f"the world {worlds[w][0] or 'unperturbed'} {worlds[w][1]:+g} stopped: "
                                      f"{result['stopped']}; the differences need every world to finish: a smaller "
                                      "chemistry step (--set dt=...) or a shorter run")  # fmt: skip
    return batch.traces

"""The walkers in the quasi-static limit ζ → 0 (docs/theory/dynamics.md, "The quasi-static limit"): the shell in
equilibrium on the ground at every chemistry step, friction alone deciding where it goes.

    wavewarp bench quasi_static_crawler --scene sphere-walker --periods 4 --device cuda --out benchmarks/results
    wavewarp bench quasi_static_crawler --scene sphere-walker --quick --device cpu

Each twin (sensitive, insensitive) is one `QuasiStatic` run of the scene's shell and FHN wave with a
`RestingGround`: the scene's ground as the area law (k per rest area a = the mean rest area per control point),
its gravity and Coulomb friction μ, one relaxation per chemistry step from where the last one left the shell,
its loads and anchors those of the last equilibrium (float64: the crawl's forces are far below float32's
relaxation floor); a relaxation that spends its CG budget is kept where it stopped and counted
(`unconverged_relaxations`, QuasiStatic's overdamped update). The shell is put down by the first relaxation. Measured as the scenes' runs are
(`wavewarp.measurements.locomotion`: the period, the speed along the wave in R per period, each pulse's
displacement; `BodyRotation`: the rolling angle, every chemistry step) and by its snaps: the steps in which a
control point moved more than SNAP R (a jump between equilibria, whose path the quasi-static limit does not
define) and the largest move in one step. Writes quasi_static_crawler_<scene>_<device>.json and .png (the centre's forward displacement
against t/T, both twins), after each twin.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from datetime import date

import numpy as np
import warp as wp

from wavewarp import QuasiStatic, RestingGround
from wavewarp.chemistry import fhn_kinetic_period
from wavewarp.device import describe_device, device_tag, resolve_device
from wavewarp.figures import locomotion_png
from wavewarp.initial import gaussian_pulse
from wavewarp.io import write_result
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.measurements import BodyRotation, locomotion
from wavewarp.parameters import load_scene, resolve
from wavewarp.runs import mean_edge
from wavewarp.walker import AUTO_DT_SAFETY, place_walker, walker_model

SCENES = ("sphere-walker", "prism-walker", "cube-walker")
SNAP = 0.05  # a chemistry step that moves a control point farther than this (in R) is counted as a snap


def crawler(scene: str, p, device, smoothing: float, tol: float):
    """The scene's shell with a RestingGround, its FHN wave and their QuasiStatic coupling; (coupled, placement,
    the control points' rest masses, the scene's options)."""
    module = load_scene(scene)
    mesh, options = module.recipe(p, device=device, report=lambda *_: None)
    placed = place_walker(mesh, replace(p, contact="area"), options["origin"])
    model = walker_model(placed.mesh, [p], placed.ground, size=options["size"], bilayer=options.get("bilayer", False),
                         rule=options.get("rule", "3"), device=device)  # fmt: skip
    shell = model.shell
    shell.terms = (RestingGround(shell, stiffness=placed.ground.stiffness, density=p.density, gravity=p.gravity,
                                 friction=p.friction, smoothing=smoothing * shell.edge_length),)  # fmt: skip
    x0 = placed.mesh.vertices
    operator = model.operator(x0 if p.sensitive else None, assembled=not p.sensitive)
    radius = options["radius"]
    width = p.width or 1.5 * mean_edge(placed.mesh)
    c0, _ = gaussian_pulse(operator, placed.origin_vertex, width / radius, gamma=p.gamma, radius=radius)
    t_end = p.periods * fhn_kinetic_period(p.nu, p.kappa, p.epsilon)
    dt = p.dt or min(AUTO_DT_SAFETY * model.wave(operator, c0=c0).stable_dt, t_end / p.frames)
    wave = model.wave(operator, c0=c0, dt=dt)
    coupled = QuasiStatic(shell, wave, sensitive=p.sensitive, x0=x0, method="ncg", tol=tol, accept_unconverged=True)
    masses = p.density * LaplaceBeltrami(placed.mesh, rule=shell.rule, device="cpu", dtype="float64").mass()
    return coupled, placed, masses, options


def run_twin(scene: str, p, device, smoothing: float, tol: float, report=print) -> dict:
    """One twin's run: the trace (t, c at the origin, centre of mass, origin) every chemistry step, the
    measurements and the relaxations' cost."""
    start = time.perf_counter()
    coupled, placed, masses, options = crawler(scene, p, device, smoothing, tol)
    wave, v = coupled.wave, placed.origin_vertex
    rotation, moves, last = BodyRotation(masses), [], [coupled.positions()]

    def row():
        x = coupled.positions()
        rotation.record(x)
        moves.append(float(np.abs(x - last[0]).max()) / options["radius"])
        last[0] = x
        return [wave.time, float(wave.c.numpy()[v]), *(masses @ x / masses.sum()), *x[v]]

    trace = [row()]
    rest_height = trace[0][4]
    steps = round(p.periods * fhn_kinetic_period(p.nu, p.kappa, p.epsilon) / wave.dt)
    for k in range(steps):
        coupled.step()
        trace.append(row())
        if (k + 1) % max(1, steps // 10) == 0:
            report(f"{scene} {'sensitive' if p.sensitive else 'insensitive'}: step {k + 1} of {steps}, "
                   f"{coupled.relax_iterations_mean():.0f} CG iterations a relaxation")  # fmt: skip
    trace = np.array(trace)
    measured = locomotion(trace, placed.forward, options["radius"], rest_height,
                          fhn_kinetic_period(p.nu, p.kappa, p.epsilon))  # fmt: skip
    return {"sensitive": p.sensitive, "trace": trace, "forward": placed.forward, "radius": options["radius"],
            "chemistry_dt": wave.dt, "chemistry_steps": steps, **coupled.counters(),
            "largest_step_move_R": max(moves), "snaps": sum(move > SNAP for move in moves),
            "wall_time_s": time.perf_counter() - start, **measured, **rotation.measurements(placed.forward)}  # fmt: skip


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench quasi_static_crawler", description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="sphere-walker", choices=SCENES)
    parser.add_argument("--device", default=None)
    parser.add_argument("--periods", type=float, default=None, help="kinetic periods (default: the scene's)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a scene parameter")
    parser.add_argument("--smoothing", type=float, default=1e-6, help="the friction's ε in mean control edges")
    parser.add_argument("--tol", type=float, default=1e-9, help="each relaxation's max |F| / (Y h ℓ̄)")
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--quick", action="store_true", help="the scene's quick mesh")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    wp.config.log_level = wp.LOG_WARNING
    module = load_scene(args.scene)
    overrides = [*args.set] + ([f"periods={args.periods}"] if args.periods else [])
    base = resolve(module.Parameters, module.QUICK if args.quick else None, [*overrides, "dtype=float64"])
    twins = []

    def chart(result, path):
        locomotion_png([(args.scene, t["sensitive"], t["trace"], t["forward"], t["radius"]) for t in twins], path,
                       title=f"{args.scene}, quasi-static crawler (ζ → 0), {result['device_name']}")  # fmt: skip

    for sensitive in (True, False):  # written after each twin: a killed run keeps the finished one
        twins.append(run_twin(args.scene, replace(base, sensitive=sensitive), device, args.smoothing, args.tol))
        runs = [{k: v for k, v in twin.items() if k not in ("trace", "forward")} for twin in twins]
        result = dict(benchmark="quasi_static_crawler", date=date.today().isoformat(), **describe_device(device),
                      scene=args.scene, quick=args.quick, settings=list(args.set), smoothing=args.smoothing,
                      tol=args.tol, twins=runs)  # fmt: skip
        write_result(result, args.out, f"quasi_static_crawler_{args.scene}_{device_tag(device)}", chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())

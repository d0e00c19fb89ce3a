"""The walkers' overdamped mechanics, explicit against implicit, side by side (issue 58).

    wavewarp bench implicit_mechanics [--device D] [--level 4] [--periods 0.25] [--dtypes float32 float64]
                                      [--substeps 1 4] [--ground-passes 1] [--out benchmarks/results] [--quick]

Runs the sphere walker (its defaults but the level and the length) with `mechanics=overdamped` (explicit Euler under
its bending bound) and `mechanics=overdamped-implicit` at each `--substeps` (backward-Euler steps per chemistry
step) and each `--ground-passes` (the ground's solve and the minimisation repeated), in each dtype, one after another in this process. Per run: the build's and the walk's wall time (the walk:
every frame after the build, kernels compiled by the build), the mechanics step and substeps, the implicit step's
mean CG iterations, and the centre of mass's displacement along the wave (in R). Per run beside it: the walk's
speed-up over the explicit run of its dtype and the displacement's difference from the explicit float64 run (or the
first explicit run when float64 is not asked for). Writes implicit_mechanics_<device>.json.
"""

from __future__ import annotations

import argparse
import time
from datetime import date

QUICK = {"level": 2, "periods": 0.1}


def walk(device: str, level: int, periods: float, dtype: str, mechanics: str, substeps: int, passes: int) -> dict:
    """One sphere walker to `periods` T₀: its timings and displacement."""
    import warp as wp

    from wavewarp.parameters import load_scene, resolve

    wp.config.log_level = wp.LOG_WARNING
    module = load_scene("sphere-walker")
    sets = [f"level={level}", f"periods={periods}", "frames=2", f"dtype={dtype}", f"mechanics={mechanics}"]
    if mechanics == "overdamped-implicit":
        sets += [f"implicit_substeps={substeps}", f"ground_passes={passes}"]
    p = resolve(module.Parameters, None, sets)
    start = time.perf_counter()
    run = module.build(p, device=device, report=lambda message: None)
    built = time.perf_counter()
    centre = run.dynamics.center_of_mass()
    for _ in range(run.frames):
        run.advance_frame()
    wp.synchronize_device(run.shell.device)
    walked = time.perf_counter()
    moved = run.dynamics.center_of_mass() - centre
    iterations = run.dynamics.mean_iterations() if hasattr(run.dynamics, "mean_iterations") else None
    implicit = iterations is not None
    return {"mechanics": mechanics, "dtype": dtype, "implicit_substeps": substeps if implicit else None,
            "ground_passes": passes if implicit else None,
            "build_s": built - start, "walk_s": walked - built, "time": run.time,
            "mechanics_dt": run.dynamics.dt, "substeps": run.coupled.substeps,
            "cg_iterations": None if iterations is None else float(iterations.mean()),
            "displacement_R": float(moved @ run.forward / p.radius)}


def compare(runs: list) -> None:
    """Each run's speed-up over its dtype's explicit run and its displacement against the reference run."""
    explicit = {r["dtype"]: r for r in runs if r["mechanics"] == "overdamped"}
    reference = explicit.get("float64") or next(iter(explicit.values()))
    for r in runs:
        r["speed_up"] = explicit[r["dtype"]]["walk_s"] / r["walk_s"]
        r["displacement_difference"] = r["displacement_R"] / reference["displacement_R"] - 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench implicit_mechanics", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--level", type=int, default=4, help="the sphere's icosphere level")
    parser.add_argument("--periods", type=float, default=0.25, help="run length in kinetic periods T₀")
    parser.add_argument("--dtypes", nargs="+", default=["float32", "float64"], choices=["float32", "float64"])
    parser.add_argument("--substeps", nargs="+", type=int, default=[1, 4], help="implicit steps per chemistry step")
    parser.add_argument("--ground-passes", nargs="+", type=int, default=[1], help="the ground's passes a step")
    parser.add_argument("--out", default="benchmarks/results", help="folder of implicit_mechanics_<device>.json")
    parser.add_argument("--quick", action="store_true", help="level 2 to 0.1 T₀ (a smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.level, args.periods = QUICK["level"], QUICK["periods"]
    if args.level < 1 or args.periods <= 0 or min(args.substeps) < 1 or min(args.ground_passes) < 1:
        parser.error("--level, --substeps and --ground-passes must be >= 1 and --periods > 0")

    import os

    from wavewarp.device import describe_device, device_tag, resolve_device
    from wavewarp.io import write_json

    device = resolve_device(args.device)
    runs = []
    for dtype in args.dtypes:
        runs.append(walk(device.alias, args.level, args.periods, dtype, "overdamped", 1, 1))
        runs += [walk(device.alias, args.level, args.periods, dtype, "overdamped-implicit", n, passes)
                 for n in args.substeps for passes in args.ground_passes]
    compare(runs)
    print(f"{'mechanics':<26} {'dtype':<8} {'steps/chem':>10} {'CG it.':>7} {'walk s':>8} {'speed-up':>9} "
          f"{'displacement R':>15} {'vs reference':>13}")
    for r in runs:
        name = r["mechanics"] + (f" ×{r['implicit_substeps']}, {r['ground_passes']}p" if r["implicit_substeps"] else "")
        iterations = "" if r["cg_iterations"] is None else f"{r['cg_iterations']:.1f}"
        print(f"{name:<26} {r['dtype']:<8} {r['substeps']:>10} {iterations:>7} {r['walk_s']:>8.2f} "
              f"{r['speed_up']:>8.1f}× {r['displacement_R']:>15.4e} {100 * r['displacement_difference']:>12.1f}%")
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"implicit_mechanics_{device_tag(device)}{'_quick' if args.quick else ''}.json")
    write_json(path, {"scene": "sphere-walker", "level": args.level, "periods": args.periods,
                      "machine": describe_device(device), "date": date.today().isoformat(), "runs": runs})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

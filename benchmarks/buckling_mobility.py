"""Buckling with lagging mechanics (issue 5 probe, docs/theory/scenes.md): the `buckling` scene's shell and
wave, stepped by the overdamped mobility model (`OverdampedDynamics`, no ground or gravity) instead
of quasi-static relaxations, to see whether a shell that lags its reference buckles into the n-fold
sequence of the paper's Fig. S1a.

    wavewarp bench buckling_mobility --device cuda --level 5 --substeps 3000 10000 --out DIR

`--substeps N` mechanics steps per chemistry step set the drag ζ = ω² dt_c / (2 · 0.9 · N) (0.9 of
the bound 2ζ/ω² per step): few substeps, a shell that lags its reference far; many, the
quasi-static limit. Every half time unit it records the symmetry number n and its amplitude (in h)
on the ring at the wave front (`scene.symmetry_number`) and the pole-to-pole height / R (2: a
sphere; smaller: the cap everts). Writes buckling_mobility.json (rows t, n, amplitude, height).
"""

from __future__ import annotations

import argparse
import math
import os
import time


def run_buckling(substeps: int, *, device, level: int, dtype: str, t_end: float = 0.0) -> dict:
    """One buckling run with N = `substeps` mobility steps per chemistry step."""
    from wavewarp.coupled import Walking
    from wavewarp.dynamics import OverdampedDynamics
    from wavewarp.measurements import symmetry_number
    from wavewarp.parameters import load_scene, resolve
    from wavewarp.waves import BlowUpError, OscillationError, TimeStepError

    module = load_scene("buckling")
    # the mobility model steps the shell without relaxations, so it has no self-contact (wavewarp/self_contact.py)
    p = resolve(module.Parameters, None, [f"level={level}", f"dtype={dtype}", f"t_end={t_end}", "self_contact=false"])
    run = module.build(p, device=device, report=lambda message: None)
    x0 = run.coupled.positions()  # the scene's first relaxation under the initial pulse
    omega = OverdampedDynamics(run.shell, density=1.0, drag=1.0, x0=x0).omega_max
    dt_c = run.wave.dt
    drag = omega**2 * dt_c / (2 * 0.9 * substeps)
    dynamics = OverdampedDynamics(run.shell, density=1.0, drag=drag, x0=x0, omega=omega, check_every=10**9)
    coupled = Walking(dynamics, run.wave, sensitive=True, check_every=max(1, 2000 // substeps))
    t_stop = p.t_end or math.pi * p.radius / p.gamma
    rows, status, start = [], "done", time.perf_counter()
    while run.wave.time < t_stop:
        try:
            coupled.advance(max(1, round(0.5 / dt_c)))
        except (BlowUpError, OscillationError, TimeStepError) as error:
            status = f"{type(error).__name__}: {error}"
            break
        run.profile_time = run.wave.time
        x = dynamics.positions()
        n, amplitude = symmetry_number(run, x)
        rows.append([run.wave.time, n, amplitude, float(x[:, 2].max() - x[:, 2].min()) / p.radius])
    return {"substeps": coupled.substeps, "drag": drag, "omega_max": omega, "dt_c": dt_c, "status": status,
            "wall_time_s": time.perf_counter() - start, "columns": ["t", "n", "amplitude_h", "height_R"], "rows": rows}  # fmt: skip


def main(argv=None) -> int:
    import warp as wp

    from wavewarp.device import describe_device, resolve_device
    from wavewarp.io import write_json

    parser = argparse.ArgumentParser(prog="wavewarp bench buckling_mobility", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default=".", help="folder for buckling_mobility.json")
    parser.add_argument("--level", type=int, default=4, help="icosphere level (default 4, the scene's)")
    parser.add_argument("--dtype", default="float64", choices=("float32", "float64"))
    parser.add_argument("--substeps", type=int, nargs="+", default=[10, 100, 1000, 3000])
    parser.add_argument("--t-end", type=float, default=0.0, help="end time (0: the wave's pole-to-pole time)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    runs = []
    for substeps in args.substeps:
        runs.append(run_buckling(substeps, device=str(device), level=args.level, dtype=args.dtype, t_end=args.t_end))
        r = runs[-1]
        peak = max(r["rows"], key=lambda row: row[2], default=[0, 0, 0.0, 2.0])
        print(f"substeps {substeps:6d}  ζ = {r['drag']:.3g}  largest mode n = {peak[1]} ({peak[2]:.2f} h) at t = "
              f"{peak[0]:.1f}  lowest height {min(row[3] for row in r['rows']):.2f} R  {r['status'][:60]}  "
              f"({r['wall_time_s']:.1f} s)", flush=True)  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "buckling_mobility.json")
    write_json(path, {"benchmark": "buckling_mobility", **describe_device(device), "level": args.level,
                      "dtype": args.dtype, "runs": runs})  # fmt: skip
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

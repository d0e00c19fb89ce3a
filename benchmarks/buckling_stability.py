"""Stability of the buckling scene's quasi-static path: does it lose stability to an n-fold mode?

Issue 5, docs/theory/scenes.md: the shell under the paper's Gaussian wave (AI = 11, R/h = 20, supplement
Fig. S1a).

    wavewarp bench buckling_stability --device cpu --level 4 --out DIR
    wavewarp bench buckling_stability --device cpu --h5 RUN.h5 --out DIR   # a stored run's frames

The `buckling` scene without its seeded imperfection and without self-contact, in float64 with
Newton-finished relaxations (`relax_method=auto`, tolerance 1e-9): the path a perfect sphere takes,
axisymmetric up to the icosphere's imprint. Or, with `--h5`, the frames of any quasi-static sphere
scene's trajectory made without self-contact (for example a level-5 path run on a GPU).
At every frame the softest modes of the shell's Hessian (`wavewarp.modes.softest_modes`, per unit
area, rigid motions removed; in units of Y h / R²), each with its azimuthal order m about the wave's
axis and the mean rest polar angle it lives at. A negative value would mark the frame where the path
buckles, and its m the pattern. Beside them the shell's largest azimuthal shape mode
(`scene.shape_asymmetry`, in h) shows where the path has left axisymmetry. At the `--bump-frames` it
also relaxes finite n-fold bumps (amplitude `--bump` × h, m = 3…8, a Gaussian band 0.2 rad wide about
the front's ring) under the same reference: a bump that decays back (energy and positions of the
symmetric state) finds no buckled equilibrium near the path. Writes buckling_stability.json and .png.
"""

from __future__ import annotations

import argparse
import math
import os
import time

from dataclasses import replace

import numpy as np

BUMP_ORDERS = (3, 4, 5, 6, 8)


def perfect_path(*, device, level: int, t_end: float, frames: int):
    """The buckling scene's run for a perfect sphere (no imperfection, no self-contact, float64,
    Newton-finished relaxations), and its frames (x, c) as it advances."""
    from wavewarp.parameters import load_scene, resolve

    module = load_scene("buckling")
    p = resolve(module.Parameters, None, [f"level={level}", "dtype=float64", "noise=0", "self_contact=false",
                                          "relax_method=auto", "accept_unconverged=false", f"t_end={t_end}",
                                          f"frames={frames}"])  # fmt: skip
    run = module.build(p, device=device, report=lambda message: None)

    def frames_of_run():
        for frame in range(run.frames + 1):
            if frame > 0:
                run.advance_frame()
            yield run.time, run.coupled.positions(), run.wave.concentration()

    return run, frames_of_run()


def stored_path(path: str, *, device):
    """A quasi-static sphere scene's frames from its HDF5 trajectory (`wavewarp run SCENE --h5`), on a
    float64 twin of its run (its stored rest mesh, so the same imperfection)."""
    import json

    import h5py

    from wavewarp.mesh import Mesh
    from wavewarp.parameters import load_scene, resumed

    with h5py.File(path, "r") as f:
        module = load_scene(str(f.attrs["scene"]))
        p = resumed(module.Parameters, json.loads(f.attrs["parameters"]))
        mesh = Mesh(f["mesh/rest_positions"][...], f["mesh/triangles"][...])
        times, positions, concentrations = (f[f"frames/{name}"][...] for name in ("time", "positions", "concentration"))
    if getattr(p, "self_contact", False):
        raise ValueError(f"{path}: its frames were relaxed with self-contact, which the Hessian has not; "
                         "analyse a run made with --set self_contact=false")  # fmt: skip
    p = replace(p, dtype="float64", noise=0.0, self_contact=False)  # the stored rest mesh carries the imperfection
    run = module.build(p, mesh=mesh, device=device, report=lambda message: None)
    return run, zip(times, positions, concentrations)


def stability_path(run, frames, *, count: int, bump: float, bump_frames) -> dict:
    """Softest modes at every frame (t, x, c) of `run`'s path, and finite bumps at `bump_frames`."""
    from wavewarp.modes import azimuthal_order, softest_modes
    from wavewarp.measurements import polar_coordinates, shape_asymmetry

    p, shell = run.p, run.shell
    R, h = p.radius, p.thickness
    unit = p.young * h / R**2
    theta, phi = polar_coordinates(run)  # about the wave's axis, as the scene's own measurements
    rows, bumps, start = [], [], time.perf_counter()
    for frame, (t, x, c) in enumerate(frames):
        front = (run.front_start + p.gamma * t) / R
        modes = softest_modes(shell, x, c, count)
        orders = [azimuthal_order(x, v, axis=run.origin) for v in modes.vectors]
        where = [float(np.degrees(np.sum(theta * np.sum(v**2, axis=1)) / np.sum(v**2))) for v in modes.vectors]
        asymmetry, order, _ = shape_asymmetry(run, x)
        rows.append([float(t), math.degrees(front), (modes.values / unit).tolist(), orders, where,
                     asymmetry * R / h, order])  # fmt: skip
        if frame in bump_frames:
            bumps += relaxed_bumps(shell, x, c, theta, phi, front, bump * h, h)
    kept = ("radius", "thickness", "AI", "AC", "width", "level", "young")
    return {"scene": run.name, "parameters": {k: getattr(p, k) for k in kept}, "value_unit": "Y h / R^2",
            "wall_time_s": time.perf_counter() - start,
            "columns": ["t", "front_deg", "values", "orders", "polar_deg", "asymmetry_h", "asymmetry_m"], "rows": rows,
            "bump_columns": ["front_deg", "m", "energy_change_relative", "max_distance_h", "ring_mode_h"],
            "bumps": bumps}  # fmt: skip


def relaxed_bumps(shell, x, c, theta, phi, front, amplitude, h) -> list:
    """Relax n-fold radial bumps on the front's ring from the symmetric equilibrium x; how far each
    ends from x, and the largest azimuthal mode left on the ring (in h)."""
    energy = shell.energy(x, c)
    radial = x / np.linalg.norm(x, axis=1, keepdims=True)
    ring = np.abs(theta - front) < 0.15
    rows = []
    for m in BUMP_ORDERS:
        bump = amplitude * np.cos(m * phi) * np.exp(-0.5 * ((theta - front) / 0.2) ** 2)
        relaxed = shell.relax(x + bump[:, None] * radial, c, tol=1e-7, method="auto")
        change = np.einsum("ij,ij->i", relaxed - x, radial)[ring]
        left = max(abs(np.mean(change * np.exp(-1j * q * phi[ring]))) * 2 for q in range(1, 13))
        rows.append([float(np.degrees(front)), m, (shell.energy(relaxed, c) - energy) / abs(energy),
                     float(np.linalg.norm(relaxed - x, axis=1).max() / h), float(left / h)])  # fmt: skip
    return rows


def write_figure(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wavewarp.io import write_png

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    colours = {}
    for _, front, values, orders, *_ in result["rows"]:
        for value, m in zip(values, orders):
            label = None if m in colours else f"m = {m}"
            colours.setdefault(m, f"C{len(colours) % 10}")
            ax.scatter(front, value, color=colours[m], s=14, label=label)
    ax.axhline(0.0, color="0.3", lw=0.8)
    broken = [row[1] for row in result["rows"] if row[5] > 0.1]
    if broken:
        ax.axvline(broken[0], color="0.5", ls="--", label="shape mode > 0.1 h")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_xlabel("front angle (degrees from the pole)")
    ax.set_ylabel("softest Hessian eigenvalues (Y h / R²)")
    par = result["parameters"]
    ratio = par["radius"] / par["thickness"]
    ax.set_title(f"{result['scene']} path: AI = {par['AI']:g}, R/h = {ratio:g}, level {par['level']}", fontsize=10)
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: (not labels[i].startswith("m"), len(labels[i]), labels[i]))
    ax.legend([handles[i] for i in order], [labels[i] for i in order], fontsize=8, ncol=2)
    fig.tight_layout()
    write_png(fig, path)
    plt.close(fig)


def main(argv=None) -> int:
    import warp as wp

    from wavewarp.device import describe_device, resolve_device
    from wavewarp.io import write_json

    parser = argparse.ArgumentParser(prog="wavewarp bench buckling_stability", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default=".", help="folder for buckling_stability.json and .png")
    parser.add_argument("--level", type=int, default=4, help="icosphere level (default 4, the scene's)")
    parser.add_argument("--t-end", type=float, default=13.2, help="end time (default 13.2: the front at 76°, past "
                        "where the everted pole meets the far side)")  # fmt: skip
    parser.add_argument("--frames", type=int, default=24, help="frames analysed (the scene's frames parameter)")
    parser.add_argument("--h5", default=None, help="analyse the frames of this trajectory (`wavewarp run SCENE --h5`, "
                        "a quasi-static sphere scene without self-contact) instead of running the perfect path")
    parser.add_argument("--modes", type=int, default=6, help="softest modes per frame")
    parser.add_argument("--bump", type=float, default=2.0, help="bump amplitude in h")
    parser.add_argument("--bump-frames", type=int, nargs="*", default=[9, 14, 18],
                        help="frames whose state gets the finite bumps (default: fronts at ~30°, 46°, 59°)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    if args.h5:
        run, frames = stored_path(args.h5, device=str(device))
    else:
        run, frames = perfect_path(device=str(device), level=args.level, t_end=args.t_end, frames=args.frames)
    result = stability_path(run, frames, count=args.modes, bump=args.bump, bump_frames=set(args.bump_frames))
    for t, front, values, orders, where, asymmetry, order in result["rows"]:
        pairs = "  ".join(f"{v:+.3e} (m={m}, θ={w:.0f}°)" for v, m, w in list(zip(values, orders, where))[:4])
        print(f"t = {t:5.2f}  front {front:3.0f}°  shape mode {order}: {asymmetry:.3f} h  {pairs}", flush=True)
    for front, m, change, distance, left in result["bumps"]:
        print(f"front {front:3.0f}°  bump m = {m}: relaxed energy change {change:+.1e} (relative), "
              f"ends {distance:.3f} h from the symmetric state, ring mode left {left:.3f} h")  # fmt: skip
    negative = [row for row in result["rows"] if min(row[2]) < 0]
    print("the path stays stable" if not negative else f"first negative eigenvalue at t = {negative[0][0]:.2f} "
          f"(front {negative[0][1]:.0f}°, m = {negative[0][3][0]})")  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "buckling_stability.json")
    write_json(path, {"benchmark": "buckling_stability", **describe_device(device), "source": args.h5 or "perfect path",
                      **result})
    write_figure(result, os.path.join(args.out, "buckling_stability.png"))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Command line: `wavewarp --version`, `wavewarp list`, `wavewarp run`, `wavewarp render` (SPEC §9)."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import signal
import sys
import time

import numpy as np


def _list(args) -> int:
    from .scene import scene_descriptions

    scenes = scene_descriptions()
    if not scenes:
        print("no scenes installed yet; `wavewarp render` draws a limit surface to USD")
    for name, description in scenes.items():
        print(f"{name:20s} {description}")
    return 0


class _Progress:
    """A one-line progress bar on a terminal's stderr; silent otherwise."""

    def __init__(self, label: str, total: int):
        self.label, self.total, self.active = label, total, sys.stderr.isatty()
        self.start = time.perf_counter()

    def update(self, done: int, sim_time: float) -> None:
        if not self.active:
            return
        width = 30
        filled = int(width * done / max(self.total, 1))
        elapsed = time.perf_counter() - self.start
        print(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] frame {done}/{self.total} t = {sim_time:.4g} "
              f"({elapsed:.0f} s)", end="", file=sys.stderr, flush=True)  # fmt: skip

    def close(self) -> None:
        if self.active:
            print(file=sys.stderr)


def _scene_run(args) -> int:
    import warp as wp

    from .io import check_writable
    from .mesh import load
    from .scene import load_scene, resolve, resumed
    from .relax import RelaxationError
    from .trajectory import TrajectoryWriter, last_frame
    from .usd import UsdAnimation
    from .waves import BlowUpError, TimeStepError

    wp.config.log_level = wp.LOG_WARNING
    start = time.perf_counter()
    module = load_scene(args.scene)
    if args.resume:
        if not args.h5 or not os.path.isfile(args.h5):
            raise ValueError("--resume needs --h5 FILE.h5, an existing trajectory of this scene")
        if args.set:
            raise ValueError(f"--set cannot be combined with --resume: the run continues with the parameters stored in {args.h5}")
        import h5py

        with h5py.File(args.h5, "r") as f:  # a parameter newer than the file: the value such files ran with
            p = resumed(module.PARAMETERS, json.loads(f.attrs["parameters"]))
        frames = _all_frames(args.h5)
    else:
        p = resolve(module.PARAMETERS, getattr(module, "QUICK", {}) if args.quick else None, args.set)
    out = args.out or f"{module.NAME}.usda"
    for path in [out] + [p for p in (args.h5, args.xdmf) if p]:
        check_writable(path)
    if args.xdmf:
        if not args.xdmf.endswith(".xdmf"):
            raise ValueError(f"XDMF output {args.xdmf!r} must end in .xdmf")
        sidecar = os.path.splitext(args.xdmf)[0] + ".h5"
        if args.h5 and os.path.abspath(sidecar) == os.path.abspath(args.h5):
            raise ValueError(f"--xdmf {args.xdmf} keeps its data in {sidecar}, the --h5 file: choose another name")

    def report(message):
        print(f"wavewarp run {module.NAME}: {message}", file=sys.stderr)

    mesh = load(args.mesh) if args.mesh else None
    run = module.build(p, mesh=mesh, device=args.device, seed=args.seed, report=report)
    usd = UsdAnimation(out, run.mesh.triangles, field_name="concentration", field_range=run.field_range,
                       ground_size=getattr(run, "ground_size", 0.0))  # fmt: skip
    h5 = None
    if args.h5:
        h5 = TrajectoryWriter(args.h5, triangles=run.mesh.triangles, rest_positions=run.mesh.vertices, series=run.series,
                              scene=module.NAME, parameters=run.resolved, device=str(run.shell.device),
                              resume=args.resume)  # fmt: skip
    xdmf = None
    if args.xdmf:
        from .geometry import limit_positions
        from .xdmf import XdmfWriter

        def limit_points(x):
            return limit_positions(run.mesh, x, device=run.operator.device, dtype="float64")

        xdmf = XdmfWriter(args.xdmf, triangles=run.mesh.triangles, rest_points=limit_points(run.mesh.vertices))

    def write(time, frame):
        usd.add_frame(frame["positions"], frame["concentration"])
        if h5 is not None:
            h5.add_frame(time, **frame)
        if xdmf is not None:
            xdmf.add_frame(time, limit_points(frame["positions"]), run.operator.field_values(frame["concentration"]))

    progress = _Progress(module.NAME, run.frames)
    interrupted, failure = False, None
    signal.signal(signal.SIGTERM, _terminate)  # a batch system's stop keeps the frames, as Ctrl-C does
    try:
        with usd, h5 or contextlib.nullcontext(), xdmf or contextlib.nullcontext():
            if args.resume:
                for k in range(len(frames["time"])):
                    frame = {name: frames[name][k] for name in frames if name != "time"}
                    usd.add_frame(frame["positions"], frame["concentration"])
                    if xdmf is not None:
                        xdmf.add_frame(frames["time"][k], limit_points(frame["positions"]),
                                       run.operator.field_values(frame["concentration"]))  # fmt: skip
                    run.record(frames["time"][k], frame, stored=True)
                run.restore(last_frame(args.h5))
                done = len(frames["time"]) - 1
            else:
                frame = run.frame()
                write(run.time, frame)
                run.record(run.time, frame)
                done = 0
            while done < run.frames:
                try:
                    run.advance_frame()
                except (BlowUpError, RelaxationError, TimeStepError) as error:  # the frames so far are complete: keep them
                    failure = str(error)
                    break
                frame = run.frame()
                write(run.time, frame)
                run.record(run.time, frame)
                done += 1
                progress.update(done, run.time)
            measured = run.measurements()
            if h5 is not None:
                h5.set_measurements(measured)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        progress.close()
    outputs = [out] + [p for p in (args.h5, args.xdmf) if p]
    if usd.frames > 1:  # the figures of the frames kept, also when the run stopped early
        outputs += run.figures(os.path.splitext(out)[0])
    summary = {
        "scene": module.NAME, "device": str(run.shell.device), "steps": run.steps, "frames": usd.frames,
        "wall_time_s": time.perf_counter() - start, "outputs": outputs, "interrupted": interrupted,
        "stopped": failure, **(run.measurements() if interrupted else measured),
    }  # fmt: skip
    if args.json:
        print(json.dumps(summary))
    if failure:
        print(f"wavewarp run {module.NAME}: {failure}; kept the {usd.frames} frames before it", file=sys.stderr)
        return 1
    if not args.json:
        state = "interrupted; kept" if interrupted else "wrote"
        print(f"{state} {usd.frames} frames to {', '.join(outputs)} ({summary['wall_time_s']:.1f} s, {run.steps} wave steps)")
    return 130 if interrupted else 0


def _terminate(signum, frame):
    raise KeyboardInterrupt


def _all_frames(path) -> dict:
    import h5py

    with h5py.File(path, "r") as f:
        return {name: f["frames"][name][...] for name in f["frames"]}


def _build_mesh(args):
    from . import mesh as meshes

    if args.mesh == "icosphere":
        mesh = meshes.icosphere(args.size, args.level)
    elif args.mesh in ("cube", "prism"):
        mesh = getattr(meshes, args.mesh)(args.size, 2 * max(args.level, 1))
    else:
        mesh = meshes.load(args.mesh)
    if mesh.needs_refinement:
        print(f"{args.mesh}: a triangle touches two extraordinary vertices; refined once by Loop subdivision", file=sys.stderr)
        mesh = mesh.refined_for_patches()
    return mesh


def _render(args) -> int:
    import warp as wp

    from .geometry import limit_positions, limit_surface
    from .usd import UsdAnimation

    wp.config.log_level = wp.LOG_WARNING
    start = time.perf_counter()
    mesh = _build_mesh(args)
    surface = limit_surface(mesh, rule=args.rule, device=args.device, dtype=args.dtype)
    # per-vertex mean curvature: area-weighted average over the vertex's triangles
    per_triangle = np.bincount(surface.triangle, surface.mean_curvature * surface.area) / np.bincount(
        surface.triangle, surface.area
    )
    weight = np.zeros(mesh.n_vertices)
    value = np.zeros(mesh.n_vertices)
    triangle_area = np.bincount(surface.triangle, surface.area)
    for k in range(3):
        np.add.at(weight, mesh.triangles[:, k], triangle_area)
        np.add.at(value, mesh.triangles[:, k], triangle_area * per_triangle)
    curvature = value / weight
    low, high = np.percentile(curvature, [1, 99])
    with UsdAnimation(args.out, mesh.triangles, field_name="meanCurvature", field_range=(low, high)) as usd:
        usd.add_frame(mesh.vertices, curvature)
    summary = {
        "mesh": args.mesh,
        "vertices": mesh.n_vertices,
        "triangles": mesh.n_triangles,
        "quadrature_points": len(surface.area),
        "area": surface.total_area,
        "gauss_bonnet_error": surface.integrate(surface.gauss_curvature) / (4 * np.pi) - 1,
        "max_limit_point_radius": float(np.linalg.norm(limit_positions(mesh, device=args.device, dtype=args.dtype), axis=1).max()),
        "device": str(surface_device(args.device)),
        "dtype": args.dtype,
        "wall_time_s": time.perf_counter() - start,
        "outputs": [args.out],
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"wrote {args.out}: {mesh.n_triangles} triangles, limit-surface area {summary['area']:.6g}, "
            f"Gauss-Bonnet error {summary['gauss_bonnet_error']:.2e} ({summary['wall_time_s']:.1f} s)"
        )
    return 0


def benchmark_names() -> list:
    """The benchmarks installed as `wavewarp.benchmarks` (the repository's benchmarks/)."""
    from wavewarp.benchmarks import NAMES

    return list(NAMES)


def _bench(args) -> int:
    names = benchmark_names()
    if args.name not in names:
        raise ValueError(f"unknown benchmark {args.name!r}; valid: {', '.join(names)}")
    return importlib.import_module(f"wavewarp.benchmarks.{args.name}").main(args.options)


def surface_device(device):
    from .device import resolve_device

    return resolve_device(device)


def main(argv=None) -> int:
    from . import __version__

    parser = argparse.ArgumentParser(prog="wavewarp", description="Chemical waves on active elastic shells.")
    parser.add_argument("--version", action="version", version=f"wavewarp {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("list", help="scene names, one line each").set_defaults(run=_list)
    run = commands.add_parser("run", help="run a scene: USD animation (and HDF5 trajectory)")
    run.add_argument("scene", help="a scene name (wavewarp list) or the path of a scene script")
    run.add_argument("--out", default=None, help="USD file (default SCENE.usda)")
    run.add_argument("--h5", default=None, help="HDF5 trajectory to write (or, with --resume, to continue)")
    run.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a scene parameter")
    run.add_argument("--xdmf", default=None, help="also write frames for ParaView (FILE.xdmf + FILE.h5)")
    run.add_argument("--mesh", default=None, help="any closed triangle mesh file in place of the scene's surface")
    run.add_argument("--quick", action="store_true", help="a reduced run for smoke tests (under a minute on a CPU)")
    run.add_argument("--seed", type=int, default=0, help="seed of the scene's random perturbations")
    run.add_argument("--resume", action="store_true", help="continue the run stored in --h5")
    run.add_argument("--json", action="store_true", help="print one JSON object with the results")
    run.set_defaults(run=_scene_run)
    render = commands.add_parser("render", help="draw a mesh's Loop limit surface to USD, coloured by mean curvature")
    render.add_argument("--mesh", default="icosphere", help="icosphere, cube, prism or a mesh file (default icosphere)")
    render.add_argument("--level", type=int, default=3, help="icosphere level, or cube/prism divisions / 2 (default 3)")
    render.add_argument("--size", type=float, default=1.0, help="sphere radius or box edge (default 1)")
    render.add_argument("--rule", default="3", help="quadrature rule: 3, 6, 7, 12 or a composite such as 3x16")
    render.add_argument("--out", default="surface.usda", help="USD file to write (default surface.usda)")
    render.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    render.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    render.add_argument("--json", action="store_true", help="print one JSON object with the results")
    render.set_defaults(run=_render)
    bench = commands.add_parser("bench", help="a benchmark: wavewarp bench NAME [--quick] [--device D] [--out DIR] ...")
    bench.add_argument("name", help=f"one of: {', '.join(benchmark_names())}")
    bench.add_argument("options", nargs=argparse.REMAINDER, help="the benchmark's own options (wavewarp bench NAME -h)")
    bench.set_defaults(run=_bench)
    args = parser.parse_args(argv)
    from .relax import RelaxationError
    from .waves import BlowUpError

    try:
        return args.run(args)
    except (ValueError, OSError) as error:
        print(f"wavewarp {args.command}: {error}", file=sys.stderr)
        return 2
    except (BlowUpError, RelaxationError) as error:  # a solver failed before the first frame
        print(f"wavewarp {args.command}: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

"""Command line: `wavewarp --version`, `wavewarp list`, `wavewarp render` (SPEC §9)."""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
import time

import numpy as np


def scene_descriptions() -> dict[str, str]:
    """Scene name -> one-line description, from the modules of `wavewarp.scenes`."""
    import wavewarp.scenes as scenes

    found = {}
    for info in pkgutil.iter_modules(scenes.__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"wavewarp.scenes.{info.name}")
        name = getattr(module, "NAME", info.name.replace("_", "-"))
        found[name] = getattr(module, "DESCRIPTION", "")
    return dict(sorted(found.items()))


def _list(args) -> int:
    scenes = scene_descriptions()
    if not scenes:
        print("no scenes installed yet; `wavewarp render` draws a limit surface to USD")
    for name, description in scenes.items():
        print(f"{name:20s} {description}")
    return 0


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
        mesh = mesh.subdivided(1)
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


def surface_device(device):
    from .device import resolve_device

    return resolve_device(device)


def main(argv=None) -> int:
    from . import __version__

    parser = argparse.ArgumentParser(prog="wavewarp", description="Chemical waves on active elastic shells.")
    parser.add_argument("--version", action="version", version=f"wavewarp {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("list", help="scene names, one line each").set_defaults(run=_list)
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
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (ValueError, OSError) as error:
        print(f"wavewarp {args.command}: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

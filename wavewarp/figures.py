"""The scenes' figures, written atomically as PNG: the rendered frame, the curvature kymograph
(Fig. 1c), the buckling symmetry number (Fig. S1a), the arrival maps of the box wave guides
(Fig. 2b) and the walkers' displacement against time (Fig. 3a).
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from .boxes import face_grid, opposite_face, unfolded_net  # noqa: E402
from .geometry import limit_positions  # noqa: E402
from .io import write_png  # noqa: E402
from .measurements import measured_period, upward_crossings  # noqa: E402
from .unfolding import first_arrival  # noqa: E402
from .usd import colour_map  # noqa: E402


def kymograph_png(run, path) -> None:
    """Fig. 1c: 1/H along the meridian (rest arc length) against time, written atomically."""
    times = [t for t, _ in run.profiles]
    image = np.array([profile[0] for _, profile in run.profiles]) / run.size
    fig, ax = plt.subplots(figsize=(6, 4.5))
    extent = (0, math.pi * run.size, times[-1] if times else 1, times[0] if times else 0)
    shown = ax.imshow(image, aspect="auto", extent=extent, cmap="RdBu", vmin=0.0, vmax=2.0)
    fig.colorbar(shown, label="local mean-curvature radius 1/H, in R")
    ax.set_xlabel("arc length from the wave's origin along a meridian (rest shell)")
    ax.set_ylabel("time")
    ax.set_title(f"{run.name}: curvature kymograph (paper Fig. 1c)")
    fig.tight_layout()
    write_png(fig, path)


def frame_png(run, path) -> None:
    """A rendered frame: the limit surface (control triangles at the limit points) coloured by c."""
    time, x, c = run.snapshot
    points = limit_positions(run.mesh, x, device=run.operator.device, dtype="float64")
    field = run.operator.field_values(c)
    triangles = run.mesh.triangles
    colours = colour_map(field[triangles].mean(axis=1), 0.0, max(float(field.max()), 1e-12))  # this frame's range
    normals = np.cross(points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]])
    light = np.clip(0.35 + 0.65 * normals @ np.array([0.4, -0.5, 0.77]) / np.linalg.norm(normals, axis=1), 0.2, 1.0)
    fig = plt.figure(figsize=(5, 5))
    ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Poly3DCollection(points[triangles], facecolors=colours * light[:, None], edgecolors="none"))
    low, high = points.min(axis=0), points.max(axis=0)
    centre, half = 0.5 * (low + high), 0.5 * np.max(high - low)
    for setter, k in ((ax.set_xlim, 0), (ax.set_ylim, 1), (ax.set_zlim, 2)):
        setter(centre[k] - half, centre[k] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=15, azim=-60)
    ax.set_axis_off()
    ax.set_title(f"{run.name}, t = {time:.3g} (colour: c from 0 to {field.max():.2g})")
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def buckling_png(run, path) -> None:
    """Fig. S1a: the buckling symmetry number n at the wave front against time."""
    fig, ax = plt.subplots(figsize=(5.8, 3.8))
    times = [t for t, _ in run.profiles]
    ax.plot(times, [value[0] for _, value in run.profiles], "o-", label="n")
    ax.axvline((0.5 * math.pi * run.size - run.front_start) / run.p.gamma, color="0.5", ls="--",
               label="front at the equator")  # fmt: skip
    ax.set_xlabel("time")
    ax.set_ylabel("symmetry number n at the front")
    amplitude = ax.twinx()  # the dominant mode's amplitude: n counts from a tenth of h
    amplitude.plot(times, [value[1] for _, value in run.profiles], color="C1", lw=1, label="its amplitude / h")
    amplitude.set_ylabel("amplitude / h", color="C1")
    ax.set_title(f"{run.name}: n-fold buckling (supplement Fig. S1a)")
    handles = [h for axis in (ax, amplitude) for h in axis.get_legend_handles_labels()[0]]
    amplitude.legend(handles, [h.get_label() for h in handles], loc="center right", fontsize=8)
    fig.tight_layout()
    write_png(fig, path)


def arrival_map_png(run, path) -> None:
    """Fig. 2b: arrival times on the unfolded net with the eikonal circles s = γ t superposed."""
    net, mask, n0 = unfolded_net(run)
    arrival = run.arrival.time
    reached = mask & (arrival > 0)
    fig, ax = plt.subplots(figsize=(5.5, 5))
    if reached.any():
        u = np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n0, u)
        plane = np.stack([(net - run.origin) @ u, (net - run.origin) @ v], axis=1)
        ax.scatter(plane[mask, 0], plane[mask, 1], c="0.85", s=4)
        shown = ax.scatter(plane[reached, 0], plane[reached, 1], c=arrival[reached], s=6, cmap="viridis")
        fig.colorbar(shown, label="arrival time (half-maximum of c)")
        for t in np.linspace(0, arrival[reached].max(), 7)[1:]:
            ax.add_patch(plt.Circle((0, 0), run.p.gamma * t, fill=False, color="k", lw=1.0, ls="--"))
    ax.set_aspect("equal")
    ax.set_title(f"{run.name} from the {getattr(run.p, 'origin', 'origin')}: arrival on the unfolded net\n"
                 "(dashed: eikonal circles s = γ t)")  # fmt: skip
    fig.tight_layout()
    write_png(fig, path)


def imprint_png(run, path, faces, fronts) -> None:
    """Arrival times on the face opposite the origin, with the borders of the exact first-arrival regions."""
    name, corners, on = opposite_face(run, faces, fronts)
    axes, gu, gv, points, inside = face_grid(corners, 160)  # even: no sample on a mirror line, where fronts tie
    plane = (run.mesh.vertices - corners[0]) @ axes.T
    arrival, triangles = run.arrival.time, run.mesh.triangles
    fig, ax = plt.subplots(figsize=(5.5, 5))
    shown = on[triangles].all(axis=1) & (arrival[triangles] > 0).all(axis=1)
    if shown.any():
        reached = arrival[on & (arrival > 0)]
        filled = ax.tripcolor(plane[:, 0], plane[:, 1], triangles[shown], arrival, shading="gouraud",
                              vmin=reached.min(), vmax=reached.max())  # fmt: skip
        fig.colorbar(filled, label="arrival time (half the first peak of c)")
    first = np.full(len(points), "", dtype=object)
    first[inside] = first_arrival(fronts(points[inside], run.origin, run.size, face=name))[1]
    for front in np.unique(first[inside]):
        ax.contour(gu, gv, np.where(inside, first == front, np.nan).astype(float).reshape(gu.shape), levels=[0.5],
                   colors="w", linewidths=1.2)  # fmt: skip
    ax.set_aspect("equal")
    ax.set_title(f"{run.name} from the {getattr(run.p, 'origin', 'origin')}: arrival on the {name} face\n"
                 f"white: the {len(np.unique(first[inside]))} exact first-arrival regions", fontsize=10)  # fmt: skip
    fig.tight_layout()
    write_png(fig, path)


def locomotion_png(runs, path, title: str = "walkers: displacement against time (paper Fig. 3a)") -> None:
    """Forward displacement of the centre of mass in R against t/T, one line per run
    (name, sensitive, trace, forward, radius); sensitive solid, insensitive dashed, as Fig. 3a."""
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for name, sensitive, trace, forward, radius in runs:
        t, c, com = trace[:, 0], trace[:, 1], trace[:, 2:5]
        scale = measured_period(upward_crossings(t, c)) or 1.0
        ax.plot(t / scale, (com - com[0]) @ np.asarray(forward) / radius, "-" if sensitive else "--",
                label=f"{name} ({'sensitive' if sensitive else 'insensitive'})")  # fmt: skip
    ax.set_xlabel("t / T (T: the measured oscillation period)")
    ax.set_ylabel("displacement / R (direction of propagation)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_png(fig, path)

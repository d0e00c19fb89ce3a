"""Box wave guides (cube, prism; paper Fig. 2): the boxes' planar faces, the unfolded net about the face
holding the origin, and the measurements against the exact geodesic field (eikonal arrival; the
imprint on the face opposite the origin, wavewarp/unfolding.py).
"""

from __future__ import annotations

import math

import numpy as np

from .mesh import Mesh
from .runs import mean_edge
from .unfolding import first_arrival


def box_faces(mesh: Mesh):
    """The planar faces of a box control mesh: (unit normal, offset) per coplanar triangle group."""
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    faces = []
    for n, p in zip(normals, a):
        if not any(np.allclose(n, m, atol=1e-9) for m, _ in faces):
            faces.append((n, float(n @ p)))
    return faces


def unfolded_net(run):
    """Rest vertex positions unfolded into the plane of the face holding the origin (that face and
    the faces sharing an edge with it), as in Fig. 2b; NaN elsewhere or when the origin lies on
    an edge or vertex. Returns (points (V, 3) in the origin face's plane, mask, its normal)."""
    x = run.mesh.vertices
    scale = np.abs(x).max()
    faces = box_faces(run.mesh)
    on = np.array([np.abs(x @ n - d) < 1e-9 * scale for n, d in faces])  # (faces, V)
    holding = [k for k, (n, d) in enumerate(faces) if abs(run.origin @ n - d) < 1e-9 * scale]
    out = np.full_like(x, np.nan)
    if len(holding) != 1:
        return out, np.zeros(len(x), dtype=bool), None
    k0 = holding[0]
    n0 = faces[k0][0]
    out[on[k0]] = x[on[k0]]
    for k, (n, _) in enumerate(faces):
        shared = on[k] & on[k0]
        if k == k0 or shared.sum() < 2:
            continue
        edge = np.cross(n, n0)
        edge /= np.linalg.norm(edge)
        angle = math.atan2(np.cross(n, n0) @ edge, n @ n0)
        K = np.array([[0, -edge[2], edge[1]], [edge[2], 0, -edge[0]], [-edge[1], edge[0], 0]])
        R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K  # Rodrigues: R n = n0
        anchor = x[np.flatnonzero(shared)[0]]
        mine = on[k] & ~on[k0]
        out[mine] = anchor + (x[mine] - anchor) @ R.T
    return out, ~np.isnan(out[:, 0]), n0


def box_wave_measurements(run) -> dict:
    """Arrival times against the distance in the unfolded net (eikonal |∇T| = 1/γ, Fig. 2b): the
    speed (slope⁻¹) and the largest deviation from the line in units of the control edge's
    crossing time; the same fit against the straight chord, which must fit worse."""
    net, mask, _ = unfolded_net(run)
    L = run.size
    distance = np.linalg.norm(net - run.origin, axis=1)
    arrival = run.arrival.time
    probe = mask & (arrival > 0) & (distance > 0.15 * L) & (distance < 0.9 * L)
    if probe.sum() < 10:
        return {"wave_speed": None, "eikonal_deviation": None, "chord_deviation": None}
    edge_time = mean_edge(run.mesh) / run.p.gamma

    def fit(d):
        slope, offset = np.polyfit(d[probe], arrival[probe], 1)
        return 1 / slope, float(np.abs(arrival[probe] - slope * d[probe] - offset).max() / edge_time)

    speed, deviation = fit(distance)
    chord = np.linalg.norm(run.mesh.vertices - run.origin, axis=1)
    return {"wave_speed": float(speed), "eikonal_deviation": deviation, "chord_deviation": fit(chord)[1]}


def face_heights(x, corners: dict) -> np.ndarray:
    """(faces, V) signed heights of points `x` above the planes of a convex box's faces (name ->
    corners, counter-clockwise from outside): all ≤ 0 inside, the largest 0 on the surface."""
    normals = [np.cross(c[1] - c[0], c[2] - c[0]) for c in corners.values()]
    return np.array([(x - c[0]) @ (n / np.linalg.norm(n)) for c, n in zip(corners.values(), normals)])


def face_grid(corners, n: int):
    """An n × n grid over a planar face's bounding rectangle. Returns the in-plane axes (2, 3) (from
    corners[0]), the grid's in-plane coordinates gu, gv (n, n), its points (n², 3) and which of them
    lie inside the face (corners counter-clockwise)."""
    u = (corners[1] - corners[0]) / np.linalg.norm(corners[1] - corners[0])
    v = corners[2] - corners[0] - ((corners[2] - corners[0]) @ u) * u
    axes = np.stack([u, v / np.linalg.norm(v)])
    c = (corners - corners[0]) @ axes.T
    gu, gv = np.meshgrid(*(np.linspace(low, high, n) for low, high in zip(c.min(axis=0), c.max(axis=0))))
    inside = np.ones(n * n, dtype=bool)
    for a, b in zip(c, np.roll(c, -1, axis=0)):  # the face lies left of each edge
        inside &= (b[0] - a[0]) * (gv.ravel() - a[1]) - (b[1] - a[1]) * (gu.ravel() - a[0]) > 1e-9 * np.ptp(c)
    return axes, gu, gv, corners[0] + np.stack([gu.ravel(), gv.ravel()], axis=1) @ axes, inside


def opposite_face(run, faces, fronts):
    """The face where the wave ends, holding the surface point farthest from the origin (on a
    61 × 61 grid per face). Returns its name, its corners and the mask of the mesh's vertices on it."""
    corners = faces(run.size)

    def farthest(name):
        _, _, _, points, inside = face_grid(corners[name], 61)
        return first_arrival(fronts(points[inside], run.origin, run.size, face=name))[0].max()

    name = max(corners, key=farthest)
    on = np.abs(face_heights(run.mesh.vertices, {name: corners[name]})[0]) < 1e-9 * run.size
    return name, corners[name], on


def imprint_measurements(run, faces, fronts) -> dict:
    """The imprint on the face opposite the origin (docs/theory/scenes.md, Fig. 2): `imprint_fold`, how many fronts
    (unfolded images of the origin) of the exact geodesic field arrive first somewhere on its
    vertices; `imprint_deviation`, the largest |arrival − (d/γ + fitted offset)| there in
    control-edge crossing times, d the exact distance; the same for the straight chord and, per
    front, for the exact field without that front (`imprint_without_front`), which must fit worse."""
    name, _, on = opposite_face(run, faces, fronts)
    x, arrival = run.mesh.vertices[on], run.arrival.time[on]
    each = fronts(x, run.origin, run.size, face=name)
    distance, first = first_arrival(each)
    out = {"imprint_face": name, "imprint_fold": len(np.unique(first)), "imprint_deviation": None,
           "imprint_chord_deviation": None, "imprint_without_front": None}  # fmt: skip
    if np.any(arrival <= 0):  # the wave has not crossed the whole face yet
        return out
    edge_time = mean_edge(run.mesh) / run.p.gamma

    def deviation(d):
        residual = arrival - d / run.p.gamma
        return float(np.abs(residual - residual.mean()).max() / edge_time)

    without = {f: deviation(np.min([each[g] for g in each if g != f], axis=0)) for f in np.unique(first)}
    return {**out, "imprint_deviation": deviation(distance),
            "imprint_chord_deviation": deviation(np.linalg.norm(x - run.origin, axis=1)),
            "imprint_without_front": without}  # fmt: skip

"""Exact geodesic distances on the triangular prism by unfolding (docs/theory/scenes.md; paper Fig. 2).

On a convex polyhedron a shortest path meets every face in one straight piece (two visits to a
convex face could be joined by the chord, which is shorter) and is therefore a straight segment
in the plane where the faces it crosses are unfolded edge to edge (Sharir & Schorr, SIAM J.
Comput. 15, 193, 1986). So d(O, P) is the least |O' − P| over the routes: face sequences
f0 ∋ O, …, fk ∋ P without repeats, O' being O unfolded into the plane of fk, counting only
routes whose line O'P passes through every unfolded shared edge. Each face lies across its
entry edge from the face before, so the crossings then follow one another between O' and P and
join by straight pieces inside the convex faces: a real path on the surface of length |O' − P|.
Each image O' sends one front of the wave, γ t = |O' − P|; where several arrive first, they meet.
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np

_TOL = 1e-9  # lengths in units of the prism's edge


def prism_faces(edge: float) -> dict:
    """The faces of `wavewarp.mesh.prism(edge)`: name -> corners (counter-clockwise seen from outside).
    Caps at z = ±edge/2, corner k at the angle 90° + 120° k (corner 0 towards +y); a side is
    named after its outward normal."""
    angles = np.pi / 2 + 2 * np.pi * np.arange(3) / 3
    ring = edge / math.sqrt(3.0) * np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], 1)
    top, bottom = ring + [0, 0, edge / 2], ring - [0, 0, edge / 2]
    return {"top": top, "bottom": bottom[::-1],
            "side-x": np.array([bottom[0], bottom[1], top[1], top[0]]),
            "side-y": np.array([bottom[1], bottom[2], top[2], top[1]]),
            "side+x": np.array([bottom[2], bottom[0], top[0], top[2]])}  # fmt: skip


def _unfold_across(points, edge, normal_from, normal_to):
    """Rotate `points` about the shared `edge` (Rodrigues) so that the face with `normal_from`
    lies in the plane of the face with `normal_to`, on the far side of the edge."""
    axis = (edge[1] - edge[0]) / np.linalg.norm(edge[1] - edge[0])
    angle = math.atan2(np.cross(normal_from, normal_to) @ axis, normal_from @ normal_to)
    p = points - edge[0]
    along = np.outer(p @ axis, axis)
    return edge[0] + along + (p - along) * math.cos(angle) + np.cross(axis, p) * math.sin(angle)


@functools.cache
def _unit_prism():
    """The unit prism's faces, their outward normals, every route (shortest first), a function
    unfolding points along a route, and per route its crossed edges unfolded into its last face."""
    faces = prism_faces(1.0)
    normals = {f: np.cross(c[1] - c[0], c[2] - c[0]) for f, c in faces.items()}
    normals = {f: n / np.linalg.norm(n) for f, n in normals.items()}
    edges = {}
    for f, g in itertools.permutations(faces, 2):
        common = [p for p in faces[f] if np.isclose(faces[g], p).all(axis=1).any()]
        if len(common) == 2:
            edges[f, g] = np.array(common)
    routes, grow = [], [(f,) for f in faces]
    while grow:
        routes += grow
        grow = [r + (g,) for r in grow for g in faces if (r[-1], g) in edges and g not in r]

    def unfold(points, route):
        for f, g in itertools.pairwise(route):
            points = _unfold_across(points, edges[f, g], normals[f], normals[g])
        return points

    crossed = {r: [unfold(edges[f, g], r[i + 1 :]) for i, (f, g) in enumerate(itertools.pairwise(r))] for r in routes}
    return faces, normals, routes, unfold, crossed


def prism_fronts(points, origin, edge: float, face: str | None = None) -> dict:
    """The fronts reaching `points` (n, 3) from `origin`, both on the surface of `prism_faces(edge)`:
    front name -> (n,) distance |O' − P| where a route through that unfolding is a path on the
    surface, inf elsewhere. A front is one image O' in the plane of a point's face, named by its
    shortest route ('top>side-y>bottom'; routes through an origin on an edge or corner can give
    the same image). The points lie in `face`, or else each in the first face holding it."""
    faces, normals, routes, unfold, crossed = _unit_prism()
    points = np.atleast_2d(np.asarray(points, dtype=np.float64)) / edge
    origin = np.asarray(origin, dtype=np.float64) / edge

    def inside(x, f):  # on the face's plane and within its corners, x: (n, 3)
        corners, n = faces[f], normals[f]
        within = np.abs((x - corners[0]) @ n) < _TOL
        for a, b in zip(corners, np.roll(corners, -1, axis=0)):
            within &= np.cross(b - a, x - a) @ n > -_TOL
        return within

    holds = np.array([inside(points, f) if face in (None, f) else np.zeros(len(points), bool) for f in faces])
    if not holds.any(axis=0).all():
        where = "the prism surface" if face is None else f"the prism face {face!r}"
        raise ValueError(f"point {points[~holds.any(axis=0)][0] * edge} is not on {where}")
    start = [f for f in faces if inside(origin[None], f)[0]]
    if not start:
        raise ValueError(f"origin {origin * edge} is not on the prism surface")
    face_of = np.array(list(faces))[np.argmax(holds, axis=0)]
    fronts, names = {}, {}  # names: (last face, rounded image) -> front name
    for r in routes:
        mine = np.flatnonzero(face_of == r[-1])
        if r[0] not in start or not len(mine):
            continue
        image, p, n = unfold(origin[None], r)[0], points[mine], normals[r[-1]]
        valid = np.ones(len(mine), dtype=bool)
        for a, b in crossed[r]:  # the edge's ends lie on either side of the line O'P
            valid &= (np.cross(p - image, a - image) @ n) * (np.cross(p - image, b - image) @ n) < _TOL
        name = names.setdefault((r[-1], *np.round(image, 6)), ">".join(r))
        distance = fronts.setdefault(name, np.full(len(points), np.inf))
        distance[mine] = np.minimum(distance[mine], np.where(valid, np.linalg.norm(p - image, axis=1), np.inf))
    return {name: distance * edge for name, distance in fronts.items()}


def first_arrival(fronts: dict):
    """(distance, name of the front arriving first) per point, from `prism_fronts`; a tie (to 1e-9)
    goes to the front listed first, of the shorter route (as at a corner reached over two routes)."""
    names = list(fronts)
    stacked = np.array([fronts[name] for name in names])
    best = stacked.min(axis=0)
    return best, np.array(names)[np.argmax(stacked <= best * (1 + _TOL), axis=0)]


def prism_geodesic_distance(points, origin, edge: float) -> np.ndarray:
    """Exact geodesic distance on the prism surface from `origin` to each of `points` (n, 3)."""
    return first_arrival(prism_fronts(points, origin, edge))[0]

"""Symmetric quadrature rules on the parameter triangle {v, w >= 0, v + w <= 1} (docs/theory/geometry.md).

Weights sum to 1/2, the parameter triangle's area. Rules (Dunavant 1985):
"3" (degree 2, the default), "6" (degree 4), "7" (degree 5), "12" (degree 6).

Composite rules "BxS" apply base rule B on each of S = 4^k congruent sub-triangles (k
midpoint splits), e.g. "3x16". Curvature concentrated at sharp control-mesh corners (cube,
prism) is integrated far better by a composite rule than by a higher degree (docs/theory/geometry.md#quadrature).
"""

from __future__ import annotations

import numpy as np

RULES = ("3", "6", "7", "12")  # base rules; composites "3x4", "12x16", ...


def _orbit3(a: float) -> list[tuple[float, float, float]]:
    b = 1.0 - 2.0 * a
    return [(a, a, b), (a, b, a), (b, a, a)]


def _orbit6(a: float, b: float) -> list[tuple[float, float, float]]:
    c = 1.0 - a - b
    return [(a, b, c), (a, c, b), (b, a, c), (b, c, a), (c, a, b), (c, b, a)]


def _dunavant(name: str):
    if name == "3":
        return [(_orbit3(1.0 / 6.0), 1.0 / 3.0)]
    if name == "6":
        return [
            (_orbit3(0.445948490915965), 0.223381589678011),
            (_orbit3(0.091576213509771), 0.109951743655322),
        ]
    if name == "7":
        return [
            ([(1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0)], 0.225),
            (_orbit3(0.470142064105115), 0.132394152788506),
            (_orbit3(0.101286507323456), 0.125939180544827),
        ]
    if name == "12":
        return [
            (_orbit3(0.249286745170910), 0.116786275726379),
            (_orbit3(0.063089014491502), 0.050844906370207),
            (_orbit6(0.310352451033784, 0.053145049844817), 0.082851075618374),
        ]
    raise ValueError(f"unknown quadrature rule {name!r}; choose one of {', '.join(RULES)}")


def triangle_rule(name: str = "3") -> tuple[np.ndarray, np.ndarray]:
    """Points (P, 2) as (v, w) and weights (P,) of the named rule."""
    name = str(name)
    if "x" in name:
        return _composite_rule(name)
    points, weights = [], []
    for orbit, weight in _dunavant(name):
        for bary in orbit:
            points.append(bary[1:])
            weights.append(weight)
    weights = np.array(weights)
    return np.array(points), 0.5 * weights / weights.sum()


def _composite_rule(name: str) -> tuple[np.ndarray, np.ndarray]:
    base, _, count = name.partition("x")
    splits = {4**k: k for k in range(1, 6)}
    if base not in RULES or not count.isdigit() or int(count) not in splits:
        raise ValueError(
            f"unknown quadrature rule {name!r}: a composite rule is BASExS with BASE one of "
            f"{', '.join(RULES)} and S one of {', '.join(map(str, splits))} (e.g. '3x16')"
        )
    corners = [np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])]
    for _ in range(splits[int(count)]):
        corners = [
            child
            for a, b, c in corners
            for child in (
                np.array([a, (a + b) / 2, (a + c) / 2]),
                np.array([(a + b) / 2, b, (b + c) / 2]),
                np.array([(a + c) / 2, (b + c) / 2, c]),
                np.array([(b + c) / 2, (a + c) / 2, (a + b) / 2]),
            )
        ]
    base_points, base_weights = triangle_rule(base)
    points = [a + base_points[:, :1] * (b - a) + base_points[:, 1:] * (c - a) for a, b, c in corners]
    return np.concatenate(points), np.tile(base_weights / len(corners), len(corners))

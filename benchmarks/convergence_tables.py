"""The convergence tables of `wavewarp bench convergence`: observed orders and Richardson estimates.

A sequence q_0, q_1, … of one observable at steps h, h/2, h/4, … (time steps halved, or mesh levels) converges at
order p where the differences d_k = q_{k+1} − q_k shrink by 2^p a halving. From the finest three values,

    p = log2(d_{n−2} / d_{n−1}),   q* = q_n + d_{n−1} / (2^p − 1),   error = |d_{n−1}| / (2^p − 1),

the Richardson estimate of the limit and its error. A sequence whose last two differences change sign, or whose
observed order is outside ORDER_RANGE, is not in its asymptotic range: its estimate is the finest value and its error
the last difference (`asymptotic` False). A vector observable (a profile) converges in the largest difference
between successive members, and its estimate is the finest member with that error.
"""

from __future__ import annotations

import math

import numpy as np

ORDER_RANGE = (0.3, 8.0)  # observed orders outside it are read as not yet asymptotic


def richardson(values) -> dict:
    """The observed order, Richardson estimate and its error of a scalar sequence at h, h/2, h/4, … (≥ 3 values
    for an order; 2 give the last difference only). Values of None (a run that did not get there) are skipped only
    at the coarse end."""
    q = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if len(q) < 2:
        return {"values": q, "order": None, "estimate": q[-1] if q else None, "error": None, "asymptotic": False}
    d = np.diff(q)
    out = {"values": q, "differences": d.tolist(), "order": None, "estimate": q[-1], "error": abs(float(d[-1]))}
    out["asymptotic"] = False
    if len(q) >= 3 and d[-1] != 0 and d[-2] != 0 and np.sign(d[-1]) == np.sign(d[-2]):
        order = math.log2(abs(d[-2] / d[-1]))
        out["order"] = order
        if ORDER_RANGE[0] <= order <= ORDER_RANGE[1]:
            tail = float(d[-1]) / (2.0**order - 1.0)
            out.update(estimate=q[-1] + tail, error=abs(tail), asymptotic=True)
    elif len(q) >= 3 and d[-1] == 0 and d[-2] == 0:
        out.update(error=0.0, asymptotic=True)
    return out


def profile_convergence(profiles) -> dict:
    """Successive largest differences of vector members (profiles at h, h/2, …), their observed order, and the
    finest member's error estimate (Richardson on the differences' norms)."""
    members = [np.array([np.nan if v is None else v for v in p], dtype=np.float64) for p in profiles if p is not None]
    if len(members) < 2:
        return {"differences": [], "order": None, "error": None, "asymptotic": False}
    norms = [float(np.nanmax(np.abs(b - a))) for a, b in zip(members, members[1:])]  # bins both members have
    out = {"differences": norms, "order": None, "error": norms[-1], "asymptotic": False}
    if len(norms) >= 2 and norms[-1] > 0 and norms[-2] > 0:
        order = math.log2(norms[-2] / norms[-1])
        out["order"] = order
        if ORDER_RANGE[0] <= order <= ORDER_RANGE[1]:
            out.update(error=norms[-1] / (2.0**order - 1.0), asymptotic=True)
    return out


def within(value, estimate, error, tolerance: float, scale: float) -> bool | None:
    """Whether `value` lies within `tolerance` × `scale` of the converged `estimate`, counting its error."""
    if value is None or estimate is None or error is None:
        return None
    return abs(float(value) - float(estimate)) + float(error) <= tolerance * scale


def markdown_row(name: str, result: dict, digits: int = 4) -> str:
    """One table row: observable | values coarse → fine | observed order | estimate ± error."""
    values = " → ".join(_number(v, digits) for v in result.get("values", []))
    order = "—" if result.get("order") is None else f"{result['order']:.2f}"
    mark = "" if result.get("asymptotic") else " (not asymptotic)"
    estimate = "—" if result.get("estimate") is None else _number(result["estimate"], digits)
    error = "—" if result.get("error") is None else _number(result["error"], 2)
    return f"| {name} | {values} | {order} | {estimate} ± {error}{mark} |"


def _number(value, digits: int) -> str:
    value = float(value)
    return f"{value:.{digits}g}" if value != 0 else "0"


# the oocytes' headline observables and how close the default must come to the converged value: (tolerance, kind, why)
HEADLINE = {
    "wave_speed": (0.02, "relative", "2% of the front speed"),
    "speed_nonlinearity": (0.005, "absolute", "0.5% of the crossing time: the constant-speed claim's margin"),
    "arrival_spread": (0.1, "absolute", "a tenth of a ring's crossing time (a ring reads axisymmetric below 0.5)"),
    "shape_asymmetry": (0.002, "absolute", "0.2% of R: the axisymmetry claim's margin (asymmetric above 1% R)"),
    "min_concentration_expanding": (0.02, "absolute", "2% of the pulse's peak C0 = 1"),
    "min_area_ratio": (0.02, "relative", "2% of the smallest area ratio (the fold is at 1/e)"),
    "contraction_depth": (0.02, "relative", "2% of the deepest contraction"),
}


def converged_value(members: dict, name: str) -> dict | None:
    """The converged estimate of one observable from one reading's points {(level, k): measurements}: Richardson
    over the levels at the step k_ref with the most levels (of those, the largest dt), corrected for that step's
    error by Richardson over the steps at the finest level from k_ref on. Errors add. None with fewer than two
    levels."""

    def value(level, k):
        v = members.get((level, k), {}).get(name)
        return None if v is None else float(v)

    steps = {k for _, k in members}
    # the step with the most levels, the smallest of them: the time sequence from it at the finest level is longest
    k_ref = max(steps, key=lambda k: (sum(value(lv, k) is not None for lv, kk in members if kk == k), -k), default=None)
    if k_ref is None:
        return None
    levels = sorted(lv for lv, k in members if k == k_ref and value(lv, k) is not None)
    if len(levels) < 2:  # one mesh: no mesh error to state
        return None
    mesh = richardson([value(lv, k_ref) for lv in levels])
    finest = levels[-1]
    in_time = richardson([value(finest, k) for k in sorted(k for lv, k in members if lv == finest) if k >= k_ref])
    correction = 0.0 if in_time["estimate"] is None else in_time["estimate"] - value(finest, k_ref)
    error = (mesh["error"] or 0.0) + (in_time["error"] or 0.0)
    return {
        "estimate": mesh["estimate"] + correction,
        "error": error,
        "levels": levels,
        "k_ref": k_ref,
        "mesh_order": mesh["order"],
        "time_order": in_time["order"],
        "asymptotic": bool(mesh["asymptotic"] and (in_time["asymptotic"] or in_time["error"] == 0.0)),
    }


def default_errors(members: dict, level: int, k: int = 0) -> dict:
    """For each HEADLINE observable: the default's value (level, k), the converged estimate and error, the
    tolerance and whether the default lies within it (its distance plus the estimate's error)."""
    out = {}
    for name, (tolerance, kind, why) in HEADLINE.items():
        default = members.get((level, k), {}).get(name)
        best = converged_value(members, name)
        if default is None or best is None:
            continue
        scale = abs(best["estimate"]) if kind == "relative" else 1.0
        out[name] = {
            "default": float(default),
            **best,
            "tolerance": tolerance,
            "kind": kind,
            "why": why,
            "meets": within(default, best["estimate"], best["error"], tolerance, scale),
        }
    return out

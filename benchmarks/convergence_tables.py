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

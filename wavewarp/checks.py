"""Argument checks shared by the public classes: a bad value raises ValueError naming it."""

from __future__ import annotations

import math

import numpy as np


AUTOMATIC_DT = "let wavewarp choose it (dt=None in Python; --set dt=auto on the command line)"


def plain(value):
    """`value` with NumPy scalars and arrays as Python numbers and lists, for messages (no np.float64(...))."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return type(value)(plain(v) for v in value)
    return value


def positive(name: str, value) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


def finite(name: str, value) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return value


def count(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {plain(value)!r}")
    return int(value)

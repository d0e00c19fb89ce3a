"""One colour scale per run, shared by the USD file and the PNG figures.

The scale is the run's own: the 0.5 and 99.5 percentiles of the field over every frame written
(`run_range`), so one outlier vertex does not wash out the wave, and a frame's colours mean the
same in the USD animation, in the rendered frame and in every other frame.
"""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps

PERCENTILES = (0.5, 99.5)
COLOUR_MAP = "viridis"


def colour_map(values, low: float, high: float, name: str = COLOUR_MAP) -> np.ndarray:
    """(n, 3) RGB colours of `values` scaled from [low, high] by matplotlib's colormap `name`."""
    s = np.clip((np.asarray(values, dtype=np.float64) - low) / max(high - low, 1e-300), 0.0, 1.0)
    return colormaps[name](s)[:, :3]


def run_range(fields) -> tuple[float, float]:
    """(low, high): the PERCENTILES of all values in `fields` (one array per frame); a constant or
    empty field gets a range of width one around its value, so that it still maps to colours."""
    values = np.concatenate([np.ravel(np.asarray(f, dtype=np.float64)) for f in fields]) if len(fields) else np.zeros(1)
    values = values[np.isfinite(values)]
    if values.size == 0:
        values = np.zeros(1)
    low, high = (float(v) for v in np.percentile(values, PERCENTILES))
    if not high > low:
        low, high = low - 0.5, high + 0.5
    return low, high

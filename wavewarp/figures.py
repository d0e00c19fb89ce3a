"""The scenes' figures, written atomically as PNG: the rendered frame, the curvature kymograph
(Fig. 1c), the buckling symmetry number (Fig. S1a), the arrival maps of the box wave guides
(Fig. 2b) and the walkers' displacement against time (Fig. 3a).

Each `*_figure` function builds the matplotlib Figure (for tests and notebooks); its `*_png`
writes it. The scenes are nondimensional (docs/theory/scenes.md): lengths in length units, time in
the run's `time_unit`; every time axis says which. A figure without enough data to draw says in
the plot what is missing and why.
"""

from __future__ import annotations

import math
import textwrap

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.cm import ScalarMappable  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402

from .boxes import face_grid, opposite_face, unfolded_net  # noqa: E402
from .colours import COLOUR_MAP, PERCENTILES, colour_map, run_range  # noqa: E402
from .io import write_png  # noqa: E402
from .measurements import measured_period, upward_crossings  # noqa: E402
from .mesh import Mesh  # noqa: E402
from .refinement import BakedSurface  # noqa: E402
from .unfolding import first_arrival  # noqa: E402

SMOOTH_TRIANGLES = 16000  # the rendered frame refines the control mesh (once or twice) to about this many
VIEW = (15.0, -60.0)  # the rendered frame's elevation and azimuth, in degrees
FHN_TIME_UNIT = "nondimensional FitzHugh–Nagumo time units"
REACHED_ENOUGH = 3  # an arrival map needs this many reached vertices


def time_label(unit: str, what: str = "time t", width: int = 48) -> str:
    """An axis label: "`what` in `unit`" on lines of at most `width` characters."""
    return textwrap.fill(f"{what} in {unit}", width)


def length_units(run) -> str:
    """The scenes' nondimensional lengths and the run's size: 'length units, R = 10' (a box: L = 20)."""
    for name, symbol in (("radius", "R"), ("edge", "L")):
        if hasattr(run.p, name):
            return f"length units, {symbol} = {getattr(run.p, name):g}"
    return "length units"


def _say(ax, message: str, blank: bool = True) -> None:
    """Write in the plot what is missing and why (a figure with too little data to draw); `blank`: the
    axes hold nothing else, so they lose their ticks."""
    if blank:
        ax.set_xticks([])
        ax.set_yticks([])
    ax.text(0.5, 0.5, textwrap.fill(message, 52, break_on_hyphens=False), transform=ax.transAxes, ha="center",
            va="center", fontsize=9, bbox={"boxstyle": "round", "fc": "white", "ec": "0.6"})  # fmt: skip


def _at(time: float) -> str:
    """A message's time, 't = 4', with no line break inside."""
    return f"t\u00a0=\u00a0{time:.3g}"


def _round_up(value: float) -> float:
    """`value` rounded up to 1, 1.5, 2, ..., 9.5 times a power of ten (a t_end to suggest)."""
    step = 10.0 ** math.floor(math.log10(max(value, 1e-12)))
    return math.ceil(2 * value / step) / 2 * step


def _longer(run, distance: float) -> str:
    """The --set that lets the wave (width p.width) travel `distance` past its peak: a t_end to suggest."""
    needed = (distance + 4.0 * getattr(run.p, "width", 0.0)) / run.p.gamma
    return f"--set t_end={_round_up(max(needed, 1.5 * run.time)):g}"


def _extend(values, low: float, high: float) -> str:
    """The colour bar's arrows: where finite `values` fall outside [low, high]."""
    finite = np.asarray(values, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    below, above = finite.size and finite.min() < low, finite.size and finite.max() > high
    return {(True, True): "both", (True, False): "min", (False, True): "max"}.get((bool(below), bool(above)), "neither")


# ---------------------------------------------------------------------------------------------
# The rendered frame


class SmoothSurface(BakedSurface):
    """The rendered frame's surface: the control mesh refined once or twice (about SMOOTH_TRIANGLES
    triangles), built once per run; a frame's control positions and values give the limit points
    and the limit field at the refined vertices (`BakedSurface`, as the baked USD file)."""

    def __init__(self, mesh: Mesh, levels: int | None = None):
        super().__init__(mesh.triangles, levels or (1 if mesh.n_triangles * 4 >= SMOOTH_TRIANGLES else 2))

    def __call__(self, x, c) -> tuple:
        """(points (V', 3), values (V',)): the limit surface and limit field at the refined vertices."""
        return self.values(x), self.values(c)


def _camera(elevation: float, azimuth: float) -> np.ndarray:
    """Rows: the screen's right and up, and the direction towards the viewer (orthographic)."""
    e, a = math.radians(elevation), math.radians(azimuth)
    toward = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    right = np.array([-math.sin(a), math.cos(a), 0.0])
    return np.stack([right, np.cross(toward, right), toward])


def _round_length(span: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above `span` (a scale bar's length)."""
    power = 10.0 ** math.floor(math.log10(span))
    return max(m * power for m in (1, 2, 5) if m * power <= span)


def frame_figure(run, surface: SmoothSurface | None = None) -> tuple:
    """(figure, (low, high), points): the snapshot frame's smooth limit surface coloured by the limit
    field on the run's colour scale (`run_range` over every recorded frame's concentrations, as the
    USD file), with a colour bar and a scale bar; `points` are the refined limit points drawn."""
    time, x, c = run.snapshot
    surface = surface or SmoothSurface(run.mesh)
    points, field = surface(x, c)
    low, high = run_range(run.concentrations)
    triangles = surface.triangles
    corners = points[triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    if np.einsum("ij,ij->", corners[:, 0], normals) < 0:  # oriented inwards: face the normals out
        normals = -normals
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    camera = _camera(*VIEW)
    facing = normals @ camera[2] > 0  # a closed surface shows only the triangles facing the viewer
    order = np.flatnonzero(facing)[np.argsort(corners[facing].mean(axis=1) @ camera[2])]  # far to near
    light = np.array([-0.4, 0.5, 0.77]) @ camera
    shade = 0.45 + 0.55 * np.clip(normals[order] @ (light / np.linalg.norm(light)), 0.0, 1.0)
    colours = colour_map(field[triangles[order]].mean(axis=1), low, high) * shade[:, None]
    screen = corners[order] @ camera[:2].T
    fig, ax = plt.subplots(figsize=(5.6, 5))
    ax.add_collection(PolyCollection(screen, facecolors=colours, edgecolors="none", antialiased=False))  # no seams
    flat = points @ camera[:2].T
    (x0, y0), (x1, y1) = flat.min(axis=0), flat.max(axis=0)
    bar = _round_length(0.4 * (x1 - x0))
    y_bar = y0 - 0.06 * (y1 - y0)
    ax.plot([x0, x0 + bar], [y_bar, y_bar], "k-", lw=2.5, solid_capstyle="butt")
    ax.text(x0 + 0.5 * bar, y_bar - 0.02 * (y1 - y0), f"{bar:g} ({length_units(run)})", ha="center", va="top",
            fontsize=8)  # fmt: skip
    ax.set_xlim(x0 - 0.03 * (x1 - x0), x1 + 0.03 * (x1 - x0))
    ax.set_ylim(y_bar - 0.1 * (y1 - y0), y1 + 0.03 * (y1 - y0))
    ax.set_aspect("equal")
    ax.set_axis_off()
    shown = ScalarMappable(norm=Normalize(low, high), cmap=COLOUR_MAP)
    fig.colorbar(shown, ax=ax, shrink=0.8, extend=_extend(field, low, high),
                 label=f"concentration c (limit field), {low:.3g} to {high:.3g}:\nthe run's {PERCENTILES[0]:g}–"
                       f"{PERCENTILES[1]:g} percentiles over {len(run.concentrations)} frames")  # fmt: skip
    ax.set_title(f"{run.name} at t = {time:.4g}\n{textwrap.fill(run.time_unit, 72)}", fontsize=9)
    return fig, (low, high), points


def frame_png(run, path) -> tuple:
    """Write the rendered frame (`frame_figure`); returns its colour scale (low, high)."""
    fig, limits, _ = frame_figure(run)
    write_png(fig, path, dpi=110)
    return limits


# ---------------------------------------------------------------------------------------------
# Time series


def curvature_limits(values, neutral: float = 1.0, least: float = 0.05) -> tuple:
    """Colour limits symmetric about `neutral` (H·R = 1: the rest sphere) reaching the farther of
    the finite values' PERCENTILES, at least `least` away: negative curvature shows where the data
    have it."""
    finite = np.asarray(values, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    half = least
    if finite.size:
        half = max(half, *(abs(v - neutral) for v in np.percentile(finite, PERCENTILES)))
    return neutral - half, neutral + half


def _time_edges(times) -> np.ndarray:
    """Cell edges around each frame's time (half way to its neighbours)."""
    t = np.asarray(times, dtype=np.float64)
    middle = 0.5 * (t[1:] + t[:-1])
    return np.concatenate([[t[0] - (middle[0] - t[0])], middle, [t[-1] + (t[-1] - middle[-1])]])


def kymograph_figure(run) -> tuple:
    """(figure, (low, high) or None): Fig. 1c, the mean curvature H·R along the meridian (rest arc
    length) against time, on a diverging map centred on the rest sphere's 1 (`curvature_limits`)."""
    fig, ax = plt.subplots(figsize=(6.6, 4.6))
    ax.set_title(f"{run.name}: curvature kymograph (paper Fig. 1c)")
    ax.set_xlabel(textwrap.fill(f"arc length from the wave's origin along a meridian, rest shell ({length_units(run)})",
                                70))  # fmt: skip
    ax.set_ylabel(time_label(run.time_unit, width=40))
    if len(run.profiles) < 2:
        _say(ax, f"A kymograph needs at least 2 frames; this run recorded {len(run.profiles)} (raise --set frames).")
        return fig, None
    times = [t for t, _ in run.profiles]
    with np.errstate(divide="ignore", invalid="ignore"):  # the profile is 1/H: 1/inf (flat) is H = 0
        curvature = run.size / np.array([profile[0] for _, profile in run.profiles], dtype=np.float64)
    low, high = curvature_limits(curvature)
    arc = np.linspace(0.0, math.pi * run.size, curvature.shape[1] + 1)
    shown = ax.pcolormesh(arc, _time_edges(times), np.ma.masked_invalid(curvature), cmap="RdBu", vmin=low, vmax=high)
    if np.nanmin(curvature) < 0 < np.nanmax(curvature):
        ax.contour(0.5 * (arc[1:] + arc[:-1]), times, np.ma.masked_invalid(curvature), levels=[0.0], colors="k",
                   linewidths=0.8)  # fmt: skip
    ax.invert_yaxis()
    fig.colorbar(shown, extend=_extend(curvature, low, high),
                 label="mean curvature H·R (white: 1, the rest sphere)\nred: flatter; below 0 (black line) "
                       "everted;\nblue: more curved")  # fmt: skip
    fig.tight_layout()
    return fig, (low, high)


def kymograph_png(run, path) -> None:
    write_png(kymograph_figure(run)[0], path)


def buckling_figure(run):
    """Fig. S1a: the buckling symmetry number n at the wave front against time."""
    fig, ax = plt.subplots(figsize=(5.8, 3.8))
    ax.set_title(f"{run.name}: n-fold buckling (supplement Fig. S1a)")
    ax.set_xlabel(time_label(run.time_unit, width=80))
    ax.set_ylabel("symmetry number n at the front")
    if len(run.profiles) < 2:
        _say(ax, f"The symmetry number against time needs at least 2 frames; this run recorded {len(run.profiles)} "
                 "(raise --set frames).")  # fmt: skip
        return fig
    times = [t for t, _ in run.profiles]
    ax.plot(times, [value[0] for _, value in run.profiles], "o-", label="n")
    ax.axvline((0.5 * math.pi * run.size - run.front_start) / run.p.gamma, color="0.5", ls="--",
               label="front at the equator")  # fmt: skip
    amplitude = ax.twinx()  # the dominant mode's amplitude: n counts from a tenth of h
    amplitude.plot(times, [value[1] for _, value in run.profiles], color="C1", lw=1, label="its amplitude / h")
    amplitude.set_ylabel("amplitude / h", color="C1")
    handles = [h for axis in (ax, amplitude) for h in axis.get_legend_handles_labels()[0]]
    amplitude.legend(handles, [h.get_label() for h in handles], loc="center right", fontsize=8)
    fig.tight_layout()
    return fig


def buckling_png(run, path) -> None:
    write_png(buckling_figure(run), path)


# ---------------------------------------------------------------------------------------------
# Box wave guides


def arrival_map_figure(run):
    """Fig. 2b: arrival times on the unfolded net with the eikonal circles s = γ t superposed."""
    net, mask, n0 = unfolded_net(run)
    arrival = run.arrival.time
    reached = mask & (arrival > 0)
    fig, ax = plt.subplots(figsize=(5.8, 5))
    origin = getattr(run.p, "origin", "origin")
    title = f"{run.name} from the {origin}: arrival on the unfolded net\n(dashed: eikonal circles s = γ t)"
    if not mask.any():
        _say(ax, f"No net to unfold: the origin ({origin}) lies on more than one face; the arrival map unfolds "
                 "the faces around a face centre (--set origin=face).")  # fmt: skip
    elif reached.sum() < REACHED_ENOUGH:
        farthest = np.linalg.norm(net[mask] - run.origin, axis=1).max()
        _say(ax, f"The wave has reached {reached.sum()} of the net's {mask.sum()} vertices by {_at(run.time)} "
                 f"(a vertex counts once half its first peak has passed): too few to map. Run longer: "
                 f"{_longer(run, farthest)}.")  # fmt: skip
    else:
        u = np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n0, u)
        plane = np.stack([(net - run.origin) @ u, (net - run.origin) @ v], axis=1)
        ax.scatter(plane[mask, 0], plane[mask, 1], c="0.85", s=4)
        shown = ax.scatter(plane[reached, 0], plane[reached, 1], c=arrival[reached], s=6, cmap="viridis")
        fig.colorbar(shown, label=time_label(run.time_unit, "arrival time t (half-maximum of c)"))
        for t in np.linspace(0, arrival[reached].max(), 7)[1:]:
            ax.add_patch(plt.Circle((0, 0), run.p.gamma * t, fill=False, color="k", lw=1.0, ls="--"))
        ax.set_aspect("equal")
        ax.set_xlabel(f"in the net's plane, from the origin ({length_units(run)})")
        if reached.sum() < mask.sum():
            title += f"\ngrey: {mask.sum() - reached.sum()} vertices not reached by t = {run.time:.3g}"
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def arrival_map_png(run, path) -> None:
    write_png(arrival_map_figure(run), path)


def imprint_figure(run, faces, fronts):
    """Arrival times on the face opposite the origin, with the borders of the exact first-arrival regions."""
    name, corners, on = opposite_face(run, faces, fronts)
    axes, gu, gv, points, inside = face_grid(corners, 160)  # even: no sample on a mirror line, where fronts tie
    plane = (run.mesh.vertices - corners[0]) @ axes.T
    arrival, triangles = run.arrival.time, run.mesh.triangles
    fig, ax = plt.subplots(figsize=(5.8, 5))
    shown = on[triangles].all(axis=1) & (arrival[triangles] > 0).all(axis=1)
    if shown.any():
        reached = arrival[on & (arrival > 0)]
        filled = ax.tripcolor(plane[:, 0], plane[:, 1], triangles[shown], arrival, shading="gouraud",
                              vmin=reached.min(), vmax=reached.max())  # fmt: skip
        fig.colorbar(filled, label=time_label(run.time_unit, "arrival time t (half the first peak of c)"))
    distance, first = np.zeros(len(points)), np.full(len(points), "", dtype=object)
    distance[inside], first[inside] = first_arrival(fronts(points[inside], run.origin, run.size, face=name))
    for front in np.unique(first[inside]):
        ax.contour(gu, gv, np.where(inside, first == front, np.nan).astype(float).reshape(gu.shape), levels=[0.5],
                   colors="w" if shown.any() else "k", linewidths=1.2)  # fmt: skip
    waiting = int(np.sum(on & (arrival <= 0))) if shown.any() else 0  # (none shown: the message says so)
    if not shown.any():
        _say(ax, f"The wave has not reached the {name} face, opposite the origin, by {_at(run.time)}: no "
                 f"arrival to show. Run longer: {_longer(run, distance.max())}.", blank=False)  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel(f"on the {name} face ({length_units(run)})")
    lines = "white" if shown.any() else "black"
    note = f"\n{waiting} of its {on.sum()} vertices not reached by t = {run.time:.3g}" if waiting else ""
    ax.set_title(f"{run.name} from the {getattr(run.p, 'origin', 'origin')}: arrival on the {name} face\n{lines}: "
                 f"the {len(np.unique(first[inside]))} exact first-arrival regions{note}", fontsize=9)  # fmt: skip
    fig.tight_layout()
    return fig


def imprint_png(run, path, faces, fronts) -> None:
    write_png(imprint_figure(run, faces, fronts), path)


# ---------------------------------------------------------------------------------------------
# Walkers


def locomotion_figure(runs, title: str = "walkers: displacement against time (paper Fig. 3a)"):
    """Forward displacement of the centre of mass in R against t/T, one line per run (name, sensitive,
    trace, forward, radius); sensitive solid, insensitive dashed, as Fig. 3a. Against t where a run's
    period T is not measured (fewer than two upward crossings of c). Runs of the same walker and twin
    (seeds of an ensemble) are drawn as their mean with a ± one standard deviation band."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.set_title(title, fontsize=9)
    ax.set_ylabel("displacement / R (direction of propagation)")
    drawn = [run for run in runs if len(run[2]) >= 2]
    periods = [measured_period(upward_crossings(trace[:, 0], trace[:, 1])) for _, _, trace, _, _ in drawn]
    per_period = all(periods)
    ax.set_xlabel(f"t / T (T: each run's measured oscillation period;\nt and T in {FHN_TIME_UNIT})" if per_period
                  else time_label(FHN_TIME_UNIT, width=70))  # fmt: skip
    if not drawn:
        _say(ax, "No run has 2 samples of its trace yet: nothing to plot (run longer: raise --set periods).")
        return fig
    groups = {}
    for (name, sensitive, trace, forward, radius), period in zip(drawn, periods):
        t, com = trace[:, 0], trace[:, 2:5]
        curve = (t / period if per_period else t, (com - com[0]) @ np.asarray(forward) / radius, period)
        groups.setdefault((name, sensitive), []).append(curve)
    for k, ((name, sensitive), curves) in enumerate(groups.items()):
        style, twin = ("-" if sensitive else "--"), ("sensitive" if sensitive else "insensitive")
        if len(curves) == 1:
            x, y, period = curves[0]
            measured = f"T = {period:.4g}" if period else "T not measured"
            ax.plot(x, y, style, label=f"{name} ({twin}, {measured})")
            continue
        grid = np.linspace(0.0, min(x[-1] for x, _, _ in curves), 200)
        ys = np.array([np.interp(grid, x, y) for x, y, _ in curves])
        mean, sd = ys.mean(axis=0), ys.std(axis=0, ddof=1)
        line = ax.plot(grid, mean, style, label=f"{name} ({twin}, {len(curves)} seeds, mean ± sd)")[0]
        ax.fill_between(grid, mean - sd, mean + sd, color=line.get_color(), alpha=0.2)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def locomotion_png(runs, path, title: str = "walkers: displacement against time (paper Fig. 3a)") -> None:
    write_png(locomotion_figure(runs, title), path)


SWEEP_COLUMNS = ("point", "seed", "status", "frames", "steps", "wall_time_s", "device", "time")


def _number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def sweep_measure(rows, grid: list, measure: str | None) -> str | None:
    """The measurement a sweep chart shows: `measure`, else the first measurement that differs between
    points (else the first)."""
    if measure is not None:
        return measure
    columns = list(dict.fromkeys(k for row in rows for k in row if k not in SWEEP_COLUMNS and k not in grid))
    varying = [k for k in columns if len({row.get(k) for row in rows}) > 1]
    return (varying or columns or [None])[0]


def sweep_chart_figure(rows, grid: list, measure: str | None, title: str = "sweep"):
    """A measurement over a sweep's grid, the seeds' mean with their range: against the one grid
    parameter; as a table-like heat map of two; against the first, one line per combination of
    the others, for more."""
    measure = sweep_measure(rows, grid, measure)
    done = [row for row in rows if measure is not None and isinstance(row.get(measure), (int, float))
            and np.isfinite(row[measure])]  # fmt: skip
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.set_title(f"{title}: {measure} over {len(done)} of {len(rows)} points", fontsize=10)
    if not done:
        _say(ax, f"No point has a value of {measure!r} yet ({len(rows)} results): see table.csv for their status.")
        return fig
    groups = {}
    for row in done:
        groups.setdefault(tuple(str(row[name]) for name in grid), []).append(row[measure])
    if len(grid) == 2:
        xs, ys = list(dict.fromkeys(k[0] for k in groups)), list(dict.fromkeys(k[1] for k in groups))
        image = np.full((len(ys), len(xs)), np.nan)
        for (x, y), values in groups.items():
            image[ys.index(y), xs.index(x)] = np.mean(values)
        shown = ax.imshow(image, origin="lower", aspect="auto", cmap=COLOUR_MAP)
        for (j, i), value in np.ndenumerate(image):
            if np.isfinite(value):
                ax.text(i, j, f"{value:.3g}", ha="center", va="center", fontsize=7, color="w")
        ax.set_xticks(range(len(xs)), xs)
        ax.set_yticks(range(len(ys)), ys)
        ax.set_xlabel(grid[0])
        ax.set_ylabel(grid[1])
        fig.colorbar(shown, label=f"{measure} (mean over seeds)")
        return fig
    lines = {}
    for key, values in groups.items():
        lines.setdefault(key[1:], []).append((key[0] if key else "", values))
    for rest, series in lines.items():
        positions = [_number(x) for x, _ in series]
        xs = positions if all(x is not None for x in positions) else list(range(len(series)))
        means = [np.mean(v) for _, v in series]
        spread = np.array([[m - min(v), max(v) - m] for m, (_, v) in zip(means, series)]).T
        label = ", ".join(f"{n}={v}" for n, v in zip(grid[1:], rest)) or None
        ax.errorbar(xs, means, yerr=spread, marker="o", capsize=3, label=label)
        if xs != positions:
            ax.set_xticks(xs, [x for x, _ in series])
    ax.set_xlabel(grid[0] if grid else "")
    ax.set_ylabel(f"{measure} (mean; bars: range over seeds)")
    if len(lines) > 1:
        ax.legend(fontsize=8)
    return fig


def sweep_chart_png(rows, grid: list, measure: str | None, path, title: str = "sweep") -> None:
    write_png(sweep_chart_figure(rows, grid, measure, title), path)

"""Measurements of scene runs, from their frames and traces (what `--json` reports).

Oocytes and buckling: the first front's arrival times (`ArrivalTimes`), the wave's speed and
rotational symmetry, the shell's shape asymmetry, the buckling symmetry number n at the front
(docs/theory/scenes.md). Walkers: the oscillation period, the displacement and the speed in R per T,
the body's rotation (rolling) (docs/theory/dynamics.md). Box scenes: wavewarp/boxes.py.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from .geometry import limit_surface
from .runs import mean_edge


class ArrivalTimes:
    """Per vertex, when the first front arrived: the first crossing of half its first peak (the
    first local maximum of the vertex's control concentration above 1% of the initial peak; the
    larger peaks where fronts cross later do not count), interpolated between the samples taken
    at every relaxation (as the arrival checks of tests/test_waves.py). `time` is 0 where no front
    has (clearly) arrived: no such peak before the last sample, or c was above half of it at t = 0.

    A frame carries the samples taken since the previous one (`frame_samples`, in `slots` slots),
    so that a resumed run replays them (`replay`) and measures what the uninterrupted run measures."""

    def __init__(self, c0: np.ndarray, slots: int = 1):
        self._times, self._values = [0.0], [np.asarray(c0, dtype=np.float64).copy()]
        self.slots, self._framed = int(slots), 1  # samples a frame carries; samples up to the last frame

    def update(self, c: np.ndarray, time: float) -> None:
        self._times.append(float(time))
        self._values.append(np.asarray(c, dtype=np.float64).copy())

    def frame_samples(self) -> dict:
        """The samples since the last recorded frame: `relaxation_count`, `relaxation_times` (slots,) and
        `relaxation_concentration` (slots, V), zero after the count."""
        times, values = self._times[self._framed:], self._values[self._framed:]
        if len(times) > self.slots:
            raise RuntimeError(f"{len(times)} relaxations in a frame, more than the {self.slots} slots it stores")
        padded_times, padded = np.zeros(self.slots), np.zeros((self.slots, len(self._values[0])))
        padded_times[:len(times)] = times
        if values:
            padded[:len(values)] = np.array(values)
        return {"relaxation_count": np.array(len(times)), "relaxation_times": padded_times,
                "relaxation_concentration": padded}

    def framed(self) -> None:
        """A frame was written: later samples belong to the next."""
        self._framed = len(self._times)

    def replay(self, time: float, frame: dict) -> None:
        """A stored frame (a resume): its samples; a file from before they were stored gives the frame's
        concentration at its time (after t = 0)."""
        count = float(frame.get("relaxation_count", np.nan))
        if np.isfinite(count):
            for t, c in zip(frame["relaxation_times"][:int(count)], frame["relaxation_concentration"][:int(count)]):
                self.update(c, t)
        elif time > 0:
            self.update(frame["concentration"], time)
        self.framed()

    @property
    def time(self) -> np.ndarray:
        values, times = np.array(self._values), np.array(self._times)
        if len(times) < 2:  # no front has moved yet
            return np.zeros(values.shape[1])
        falls = (values[:-1] >= values[1:]) & (values[:-1] > 0.01 * values[0].max())
        falls[:1] = False  # falling from t = 0 is the initial pulse, not an arrival
        columns = np.arange(values.shape[1])
        peak = values[np.argmax(falls, axis=0), columns]
        valid = falls.any(axis=0) & (values[0] < 0.5 * peak)
        j = np.maximum(np.argmax(values >= 0.5 * peak, axis=0), 1)
        before, after = values[j - 1, columns], values[j, columns]
        fraction = np.clip((0.5 * peak - before) / np.where(after > before, after - before, 1.0), 0.0, 1.0)
        arrival = times[j - 1] + fraction * (times[j] - times[j - 1])
        return np.where(valid, arrival, 0.0)


def sphere_wave_measurements(run, theta_range=(math.pi / 4, 3 * math.pi / 4), rings=12) -> dict:
    """Wave speed and rotational symmetry of a pulse from the pole (docs/theory/scenes.md, Fig. 1c).

    Arrival times against the rest arc length R θ on θ in `theta_range`: the speed is the slope's
    inverse, `speed_nonlinearity` the largest deviation from the line over the time to cross the
    range, and `arrival_spread` the largest standard deviation of the arrival times within a
    latitude ring, over the time the wave takes to cross one ring.
    """
    R = run.size
    rest = run.mesh.vertices
    theta = np.arccos(np.clip(rest @ run.origin / (np.linalg.norm(rest, axis=1) * np.linalg.norm(run.origin)), -1, 1))
    arrival = run.arrival.time
    window = (theta > theta_range[0]) & (theta < theta_range[1])
    probe = (arrival > 0) & window
    if probe.sum() < 10 or probe.sum() < window.sum():  # the front has not crossed the whole window yet
        return {"wave_speed": None, "speed_nonlinearity": None, "arrival_spread": None}
    s, t = R * theta[probe], arrival[probe]
    slope, offset = np.polyfit(s, t, 1)
    crossing = slope * (s.max() - s.min())
    edges = np.linspace(*theta_range, rings + 1)
    ring = np.digitize(theta[probe], edges) - 1
    spread = max(float(np.std(t[ring == k])) for k in range(rings) if np.sum(ring == k) > 2)
    return {"wave_speed": float(1 / slope), "speed_nonlinearity": float(np.abs(t - (slope * s + offset)).max() / crossing),
            "arrival_spread": spread / (crossing / rings)}  # fmt: skip


# a shell reads as axisymmetric while every ring mode is below this fraction of R: the icosphere's
# imprint reads up to 0.03% on the oocytes, a buckled ascidian 5% and more (docs/theory/scenes.md)
AXISYMMETRY_TOLERANCE = 0.01


def asymmetry_measurements(run) -> dict:
    """The shell's largest shape asymmetry over the frames (shape_asymmetry: in R, and its mode),
    `axisymmetric_until`, the last frame time before one passes AXISYMMETRY_TOLERANCE (None if the
    first does), and `asymmetric_between`, the first and last frame times past it (None if none is)."""
    times = [t for t, _ in run.profiles]
    values = [value[1] for _, value in run.profiles]
    if not values:
        return {"shape_asymmetry": None, "shape_asymmetry_mode": None, "axisymmetric_until": None,
                "asymmetric_between": None}  # fmt: skip
    k = int(np.argmax([amplitude for amplitude, _, _ in values]))
    broken = [j for j, (amplitude, _, _) in enumerate(values) if amplitude > AXISYMMETRY_TOLERANCE]
    until = times[-1] if not broken else (times[broken[0] - 1] if broken[0] > 0 else None)
    between = [times[broken[0]], times[broken[-1]]] if broken else None
    return {"shape_asymmetry": values[k][0], "shape_asymmetry_mode": values[k][1], "axisymmetric_until": until,
            "asymmetric_between": between}  # fmt: skip


def oocyte_profile(run, x) -> tuple:
    """A frame's figures and checks: the meridian's curvature radius (the kymograph's row), the
    shell's shape asymmetry and its contraction profile."""
    return meridian_curvature_radius(run, x), shape_asymmetry(run, x), contraction_profile(run, x)


def oocyte_measurements(run, theta_range=(math.pi / 4, 3 * math.pi / 4)) -> dict:
    """An oocyte's measurements; `theta_range`: where the front speed is fitted (a run that ends early, a window
    its front crosses)."""
    return {**sphere_wave_measurements(run, theta_range), **asymmetry_measurements(run),
            **contraction_measurements(run), **phase_minima(run)}


def phase_minima(run) -> dict:
    """The smallest concentration (the field at the limit points) while the front expands, up to its arrival at
    the equator (rest arc length πR/2 from the origin), and after it, while it converges on the antipode."""
    equator = (0.5 * math.pi * run.size - run.front_start) / run.p.gamma
    balance = getattr(run, "balance", None)  # (a batch's world view has none)
    if balance is None:
        return dict.fromkeys(("min_concentration_expanding", "min_concentration_converging"))
    return {"min_concentration_expanding": balance.min_concentration_between(0.0, equator),
            "min_concentration_converging": balance.min_concentration_between(equator + 1e-12, math.inf)}


PROFILE_BINS = 36  # rest polar-angle bins of the contraction profile (5° each)
PROFILE_FRACTIONS = (0.25, 0.5, 0.75)  # the frames whose profiles a run reports, as fractions of its end time


def contraction_profile(run, x, bins=PROFILE_BINS) -> np.ndarray:
    """The shell's cross-section as paper Fig. 1a/b overlays it: the mean distance from the centroid, in R, of the
    control vertices in each of `bins` bins of their rest polar angle from the wave's origin (the ring average:
    an axisymmetric shell's meridian)."""
    theta, _ = polar_coordinates(run)
    x = np.asarray(x, dtype=np.float64)
    radius = np.linalg.norm(x - x.mean(axis=0), axis=1)
    index = np.minimum((theta / math.pi * bins).astype(int), bins - 1)
    counts = np.bincount(index, minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.bincount(index, radius, bins) / counts, np.nan) / run.size  # NaN: no vertex


def _listed(profile: np.ndarray) -> list:
    return [None if np.isnan(v) else float(v) for v in profile]  # JSON has no NaN


def contraction_measurements(run) -> dict:
    """`contraction_depth`: the deepest contraction over the frames, 1 − r/R of the contraction profile's lowest
    bin, with its time and rest polar angle (degrees); `contraction_profiles`: the profiles of the frames nearest
    PROFILE_FRACTIONS of the last frame's time ({time: profile})."""
    frames = [(t, value[2]) for t, value in run.profiles if len(value) > 2]
    if not frames:
        return dict.fromkeys(("contraction_depth", "contraction_depth_time", "contraction_depth_angle",
                              "contraction_profiles"))
    depths = [1.0 - float(np.nanmin(profile)) for _, profile in frames]
    k = int(np.argmax(depths))
    angle = (int(np.nanargmin(frames[k][1])) + 0.5) * 180.0 / len(frames[k][1])
    times = np.array([t for t, _ in frames])
    chosen = sorted({int(np.argmin(np.abs(times - f * times[-1]))) for f in PROFILE_FRACTIONS})
    return {
        "contraction_depth": depths[k],
        "contraction_depth_time": float(times[k]),
        "contraction_depth_angle": angle,
        "contraction_profiles": {f"{times[j]:.6g}": _listed(frames[j][1]) for j in chosen},
    }


def meridian_curvature_radius(run, x, bins=90) -> np.ndarray:
    """The local mean-curvature radius 1/H along the meridian through the origin (x > 0 half-plane
    containing the polar axis), in `bins` bins of the rest polar angle: the kymograph's rows."""
    surface = limit_surface(run.mesh, x, device=run.operator.device, dtype="float64")
    rest = limit_surface(run.mesh, device=run.operator.device, dtype="float64").points
    axis = run.origin / np.linalg.norm(run.origin)
    side = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    width = 0.5 * mean_edge(run.mesh)
    near = np.abs(rest @ side) < width
    in_plane = np.cross(side, axis)
    theta = np.arctan2(rest @ in_plane, rest @ axis) % (2 * np.pi)  # 0 at the origin, π at the antipode
    theta = np.where(theta > np.pi, 2 * np.pi - theta, theta)
    index = np.minimum((theta[near] / np.pi * bins).astype(int), bins - 1)
    curvature = np.bincount(index, surface.mean_curvature[near] * surface.area[near], bins)
    area = np.bincount(index, surface.area[near], bins)
    with np.errstate(divide="ignore", invalid="ignore"):
        return area / curvature  # 1/H, area-weighted H in each bin


def polar_coordinates(run) -> tuple:
    """Per rest vertex: its polar angle θ from the wave's origin about the sphere's centre, and its
    azimuth φ about that axis."""
    rest = run.mesh.vertices
    axis = run.origin / np.linalg.norm(run.origin)
    theta = np.arccos(np.clip(rest @ axis / np.linalg.norm(rest, axis=1), -1, 1))
    side = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    return theta, np.arctan2(rest @ np.cross(axis, side), rest @ side)


def ring_modes(radial: np.ndarray, offset: np.ndarray, phi: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """Amplitudes of the azimuthal modes `modes` of `radial` on a latitude ring (its vertices at
    polar offsets `offset` from the ring's centre and azimuths `phi`), less the ring's axisymmetric
    profile across the band (a quadratic in the offset): its slope and curvature would leak into the
    modes of the ring's irregularly placed vertices."""
    trend = np.vander(offset, 3)
    radial = radial - trend @ np.linalg.lstsq(trend, radial, rcond=None)[0]
    return np.abs(np.exp(-1j * np.outer(modes, phi)) @ radial) * 2 / len(radial)


def symmetry_number(run, x, threshold=0.1) -> tuple:
    """(n, amplitude): the dominant azimuthal mode m ≥ 2 of the radial displacement on the latitude
    ring at the wave front (rest polar angle γ t / R, one control edge wide), less its axisymmetric
    trend across the ring, and its amplitude in units of h; n = 0 while every mode is below
    `threshold` h (axisymmetric). A tenth of h: on shells that do not buckle the icosphere's imprint,
    the seeded imperfection and the irregular ring's residual read up to 0.03 h (docs/theory/scenes.md)."""
    R, rest = run.size, run.mesh.vertices
    theta, phi = polar_coordinates(run)
    front = min((run.front_start + run.p.gamma * run.profile_time) / R, math.pi)
    ring = np.abs(theta - front) < 0.5 * mean_edge(run.mesh) / R
    if ring.sum() < 8:
        return 0, 0.0
    radial = np.linalg.norm(np.asarray(x)[ring], axis=1) - np.linalg.norm(rest[ring], axis=1)
    modes = np.arange(2, max(3, ring.sum() // 2))
    amplitude = ring_modes(radial, theta[ring] - front, phi[ring], modes) / run.p.thickness
    k = int(np.argmax(amplitude))
    return (int(modes[k]) if amplitude[k] > threshold else 0), float(amplitude[k])


def shape_asymmetry(run, x) -> tuple:
    """(amplitude / R, m, θ): the largest azimuthal mode 1 ≤ m ≤ 8 of the change in distance from the
    centroid (so rigid motion reads nothing), over the latitude rings (one control edge wide) about the
    wave's axis, each less its axisymmetric profile across the ring; θ is that ring's rest polar
    angle. m = 1 is a lopsided shell."""
    R, rest, x = run.size, run.mesh.vertices, np.asarray(x)
    theta, phi = polar_coordinates(run)
    radial = np.linalg.norm(x - np.mean(x, axis=0), axis=1) - np.linalg.norm(rest - rest.mean(axis=0), axis=1)
    width = mean_edge(run.mesh) / R
    best = (0.0, 0, 0.0)
    for centre in np.arange(width, math.pi - 0.5 * width, width):
        ring = np.abs(theta - centre) < 0.5 * width
        if ring.sum() < 4 * 8:  # m ≤ 8 with four vertices per wavelength
            continue
        amplitude = ring_modes(radial[ring], theta[ring] - centre, phi[ring], np.arange(1, 9)) / R
        k = int(np.argmax(amplitude))
        if amplitude[k] > best[0]:
            best = (float(amplitude[k]), k + 1, float(centre))
    return best


def buckling_modes(numbers) -> dict:
    """A run's buckling modes from its frames' symmetry numbers: `n_onset`, the first nonzero (the mode
    the shell buckles into), and `n_mode`, the one most frames read (the smaller of a tie); 0 when no
    frame buckled (a phase diagram's entries)."""
    buckled = [int(n) for n in numbers if n]
    return {"n_onset": buckled[0] if buckled else 0,
            "n_mode": max(sorted(set(buckled)), key=buckled.count) if buckled else 0}  # fmt: skip


def buckling_measurements(run) -> dict:
    """The frames' symmetry numbers n at the front, the largest, `buckling_modes`, and `amplitude_max_h`,
    the largest ring amplitude over the frames (units of h)."""
    n = [int(value[0]) for _, value in run.profiles]
    times = [t for t, _ in run.profiles]
    k = int(np.argmax(n)) if n else 0
    return {"symmetry_numbers": n, "n_max": n[k] if n else 0, "t_n_max": times[k] if n else None,
            **buckling_modes(n), "amplitude_max_h": max((float(value[1]) for _, value in run.profiles), default=0.0),
            "t_front_at_equator": (0.5 * math.pi * run.size - run.front_start) / run.p.gamma}  # fmt: skip


def upward_crossings(t: np.ndarray, c: np.ndarray, level: float = 0.5) -> np.ndarray:
    """Times where c rises through `level`, linearly interpolated between samples."""
    k = np.flatnonzero((c[:-1] < level) & (c[1:] >= level))
    return t[k] + (level - c[k]) / (c[k + 1] - c[k]) * (t[k + 1] - t[k])


def measured_period(crossings: np.ndarray) -> float | None:
    """T: the mean interval between crossings (None with fewer than two)."""
    return float(np.mean(np.diff(crossings))) if len(crossings) >= 2 else None


def locomotion(trace: np.ndarray, forward, radius: float, rest_height: float, period_kinetic: float) -> dict:
    """Period, displacement and speed from a trace (rows: t, c at the origin, centre of mass, origin).

    T: the mean interval between upward half-maximum crossings of c at the origin (None with
    fewer than two). The speed is measured over whole periods, between the first and the last
    crossing (the first pulse's start-up excluded), in R per T along `forward` (the propagation
    direction at the start); the displacement is the whole run's. Per period k (a pulse):
    `pulse_displacements_R` its forward displacement, and `pulse_alignment` the cosine between its
    horizontal displacement and the direction of propagation at its start, the horizontal
    direction from the origin vertex (the origin turns with the shell) to the centre of mass.
    `crossing_heights_R`: the centre of mass's height at each crossing (the same phase of every
    pulse) above its height at the start, in R: a sag still settling over the run shows as a drift.
    `sag_R`: the elastic sag, how far the settled centre of mass lies below that of the rigid
    shell in the same contact (`rest_height`).
    """
    t, c, com, origin = trace[:, 0], trace[:, 1], trace[:, 2:5], trace[:, 5:8]
    forward = np.asarray(forward, dtype=np.float64)
    side = np.cross([0.0, 0.0, 1.0], forward)
    displacement = com[-1] - com[0]
    out = {"period_kinetic": period_kinetic, "period": None, "displacement": displacement.tolist(),
           "distance_R": float(displacement @ forward / radius), "lateral_R": float(displacement @ side / radius),
           "sag_R": float((rest_height - com[0, 2]) / radius), "speed_R_per_T": None, "pulse_displacements_R": [],
           "pulse_alignment": [], "crossing_heights_R": []}  # fmt: skip
    crossings = upward_crossings(t, c)
    period = measured_period(crossings)
    if period is not None:
        at = np.stack([np.interp(crossings, t, column) for column in np.hstack([com, origin]).T], axis=1)
        along = at[:, :3] @ forward
        step = np.diff(at[:, :2], axis=0)
        direction = at[:-1, :2] - at[:-1, 3:5]
        alignment = np.sum(step * direction, axis=1) / (np.linalg.norm(step, axis=1) * np.linalg.norm(direction, axis=1))
        out.update(period=period, pulse_displacements_R=(np.diff(along) / radius).tolist(),
                   crossing_heights_R=((at[:, 2] - com[0, 2]) / radius).tolist(),
                   pulse_alignment=alignment.tolist(), speed_R_per_T=float((along[-1] - along[0]) / radius / (len(crossings) - 1)))  # fmt: skip
    return out


def best_rotation(reference: np.ndarray, x: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """The rotation vector (radians) of the rotation that best carries `reference` onto `x` about their
    centres of mass, in the mass-weighted least-squares sense (Kabsch)."""
    p = reference - mass @ reference / mass.sum()
    q = x - mass @ x / mass.sum()
    u, _, vt = np.linalg.svd((p * mass[:, None]).T @ q)
    flip = np.sign(np.linalg.det(vt.T @ u.T))
    return Rotation.from_matrix(vt.T @ np.diag([1.0, 1.0, flip]) @ u.T).as_rotvec()


class BodyRotation:
    """How far a walker turned as a body: at every recorded frame, the best-fit rotation (`best_rotation`)
    from the first frame's shape; per world of a batch (worlds of equal vertex counts).

    `rolling_angle_deg`: the last frame's rotation about the horizontal axis z × forward, positive when
    the top moves forward (a ball rolling forward without slip turns by its distance / R);
    `rotation_deg` its whole angle; `max_rotation_deg` the largest whole angle over the frames."""

    def __init__(self, mass: np.ndarray, worlds: int = 1):
        self.mass, self.worlds = np.asarray(mass, dtype=np.float64), worlds
        self.reference = None
        self.rotations = []  # per frame: (worlds, 3) rotation vectors

    def record(self, positions) -> None:
        x = np.asarray(positions, dtype=np.float64).reshape(self.worlds, -1, 3)
        if self.reference is None:
            self.reference = x.copy()
        mass = self.mass.reshape(self.worlds, -1)
        self.rotations.append(np.array([best_rotation(r, xw, m) for r, xw, m in zip(self.reference, x, mass)]))

    def measurements(self, forward, world: int = 0) -> dict:
        if not self.rotations:
            return {"rolling_angle_deg": None, "rotation_deg": None, "max_rotation_deg": None}
        side = np.cross([0.0, 0.0, 1.0], np.asarray(forward, dtype=np.float64))
        rotations = np.array(self.rotations)[:, world]
        angles = np.degrees(np.linalg.norm(rotations, axis=1))
        return {"rolling_angle_deg": float(np.degrees(rotations[-1] @ side)), "rotation_deg": float(angles[-1]),
                "max_rotation_deg": float(angles.max())}

"""Telegraph and FitzHugh–Nagumo waves: invariants, exact solutions, arrival times, stability (docs/theory/chemistry.md, docs/theory/scenes.md).

Every reference here is computed independently in the test: the Legendre series of the
telegraph equation on a sphere, great-circle and unfolded-net distances, a finite-difference
1-D FitzHugh–Nagumo solve, and the time-step bounds from the operator's eigenvalues.
"""

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.polynomial import legendre
from scipy.optimize import minimize_scalar

from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import cube, icosphere
from wavewarp.kernels.waves import FLIP_FLOP, flip_kernel
from wavewarp.chemistry import FLIP_FLOOR, FLIP_HOLD, FLIP_STEPS
from wavewarp.waves import BlowUpError, FitzHughNagumo, OscillationError, Telegraph, TimeStepError
from wavewarp.initial import gaussian_pulse, steady_front

F64 = dict(device="cpu", dtype="float64")


def sphere_operator(radius, level, **kwargs):
    return LaplaceBeltrami(icosphere(radius, level), **F64, **kwargs)


# ---------------------------------------------------------------- invariants


@pytest.mark.parametrize("alpha", [0.001, 0.3])
@pytest.mark.parametrize("discretization, mass_corrections", [("subdivision", 0), ("subdivision", 2), ("p1", 0)])
def test_total_concentration_obeys_its_damped_law(alpha, discretization, mass_corrections):
    """C'' + α C' = 0 (docs/theory/chemistry.md): leapfrog's C' decays by (1 - αdt/2)/(1 + αdt/2) per step, to
    round-off, which is e^{-α dt} up to α³dt³/12 per step."""
    op = sphere_operator(1.0, 2, discretization=discretization)
    c0, v0 = gaussian_pulse(op, 0, 0.4, gamma=1.0)
    wave = Telegraph(op, 1.0, alpha, c0=c0, v0=v0, mass_corrections=mass_corrections)
    totals = [wave.total()]
    for _ in range(60):
        wave.advance(1)
        totals.append(wave.total())
    rate = np.diff(totals) / wave.dt  # C' at t_{n+½}
    assert rate[0] > 0  # outgoing pulse: the total rises
    h = 0.5 * alpha * wave.dt
    n = np.arange(len(rate))
    np.testing.assert_allclose(rate, rate[0] * ((1 - h) / (1 + h)) ** n, rtol=1e-12, atol=1e-13 * rate[0])
    initial_rate = op.mass() @ v0  # C'(0)
    t_half = (n + 0.5) * wave.dt
    bound = h**2 + (n + 1) * h**3 + 1e-12  # (1 - h) r^n against e^{-h} e^{-2hn}, h = αdt/2
    assert np.all(np.abs(rate / (initial_rate * np.exp(-alpha * t_half)) - 1) <= bound)


# ---------------------------------------------------------------- exact solution on the sphere


def legendre_solution(c0, v0, gamma, alpha, t, mu, lmax=60):
    """Telegraph equation on the unit sphere for axisymmetric data, mode by mode.

    c = Σ c_l(t) P_l(cos θ): l = 0 is overdamped, c_0 = a_0 + b_0 (1 - e^{-αt}) / α; l >= 1
    oscillates with ω_l² = γ² l(l+1) - α²/4.
    """
    x, w = legendre.leggauss(400)
    basis = np.array([legendre.legval(x, np.eye(lmax + 1)[l]) for l in range(lmax + 1)])
    norm = (2 * np.arange(lmax + 1) + 1) / 2
    a, b = norm * (basis * c0(x) * w).sum(axis=1), norm * (basis * v0(x) * w).sum(axis=1)
    assert max(abs(a[-5:]).max(), abs(b[-5:]).max()) < 1e-10  # the series has converged
    modes = np.empty(lmax + 1)
    modes[0] = a[0] + b[0] * (1 - math.exp(-alpha * t)) / alpha
    for l in range(1, lmax + 1):
        omega = math.sqrt(gamma**2 * l * (l + 1) - alpha**2 / 4)
        modes[l] = math.exp(-alpha * t / 2) * (a[l] * math.cos(omega * t) + (b[l] + alpha * a[l] / 2) / omega * math.sin(omega * t))
    return legendre.legval(mu, modes)


@pytest.mark.parametrize(
    "discretization, mass_corrections, order", [("subdivision", 0, 1.7), ("subdivision", 2, 4.0), ("p1", 0, 1.7)]
)
def test_telegraph_matches_the_legendre_series(discretization, mass_corrections, order):
    """Error at t = 2 falls with refinement at the stated order (measured: 1.9, 4.8, 1.9-2.0)."""
    gamma, alpha, sigma = 1.0, 0.1, 0.4

    def c0(mu):
        return np.exp(-np.arccos(np.clip(mu, -1, 1)) ** 2 / (2 * sigma**2))

    def v0(mu):
        return 0.2 + 0.5 * np.exp(-(1 - mu) / sigma**2)  # smooth, with a non-zero mean (l = 0)

    errors = []
    for level in (2, 3, 4):
        op = sphere_operator(1.0, level, discretization=discretization)
        mu = op.points()[:, 2]
        wave = Telegraph(op, gamma, alpha, c0=op.control_values(c0(mu)), v0=op.control_values(v0(mu)), dt=0.005,
                         mass_corrections=mass_corrections)  # fmt: skip
        wave.run_until(2.0)
        exact = legendre_solution(c0, v0, gamma, alpha, wave.time, mu)
        errors.append(np.abs(op.field_values(wave.concentration()) - exact).max() / np.abs(exact).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > order), (errors, orders)


# ---------------------------------------------------------------- front arrival s / γ


def arrival_times(op, wave, t_end, probes):
    """First time each probe's field value reaches half of its maximum over the run."""
    times, values = [wave.time], [op.field_values(wave.concentration())[probes]]
    while wave.time < t_end:
        wave.advance(1)
        times.append(wave.time)
        values.append(op.field_values(wave.concentration())[probes])
    times, values = np.array(times), np.array(values)
    half = 0.5 * values.max(axis=0)
    j = np.argmax(values >= half, axis=0)
    cols = np.arange(values.shape[1])
    before, after = values[j - 1, cols], values[j, cols]
    return times[j - 1] + (half - before) / (after - before) * (times[j] - times[j - 1])


def fit_speed(distance, times):
    """Slope 1/γ of t = s/γ + t0, and the largest deviation from that line."""
    slope, offset = np.polyfit(distance, times, 1)
    return 1 / slope, np.abs(times - (slope * distance + offset)).max()


def test_front_arrives_after_the_great_circle_distance_over_gamma():
    gamma = 1.5
    op = sphere_operator(1.0, 4)
    pole = np.array([0.0, 0.0, 1.0])
    c0, v0 = gaussian_pulse(op, pole, 0.2, gamma=gamma, radius=1.0, distance="arc")
    wave = Telegraph(op, gamma, 0.001, c0=c0, v0=v0, mass_corrections=2)
    s = np.arccos(np.clip(op.points() @ pole, -1, 1))  # great-circle distance on the unit sphere
    probes = (s > 0.5) & (s < 2.5)
    speed, deviation = fit_speed(s[probes], arrival_times(op, wave, 3.0 / gamma, probes))
    assert speed == pytest.approx(gamma, rel=0.02)  # measured 0.5%
    assert deviation < 0.01 / gamma  # one front on every meridian


def test_front_arrives_after_the_unfolded_net_distance_over_gamma_on_a_cube():
    """Wave from the top face centre; a point on a side face is reached across the shared edge,
    at its distance in the net unfolded about that edge (the limit surface's faces are flat)."""
    op = LaplaceBeltrami(cube(2.0, 16), **F64)
    x, y, z = op.points().T
    c0, v0 = gaussian_pulse(op, np.array([0.0, 0.0, 1.0]), 0.2, gamma=1.0, radius=1.0)
    wave = Telegraph(op, 1.0, 0.001, c0=c0, v0=v0, safety=0.5)
    top, side = np.abs(z - 1) < 1e-9, np.abs(np.abs(x) - 1) < 1e-9
    unfolded = np.where(top, np.hypot(x, y), np.hypot(2 - z, y))
    probes = (top | side) & (unfolded > 0.4) & (unfolded < 2.0) & (np.abs(y) < 0.5)
    times = arrival_times(op, wave, 3.0, probes)
    speed, deviation = fit_speed(unfolded[probes], times)
    assert speed == pytest.approx(1.0, rel=0.03)  # measured 0.5%
    assert deviation < 0.04
    chord = np.linalg.norm(op.points() - [0.0, 0.0, 1.0], axis=1)
    assert fit_speed(chord[probes], times)[1] > 5 * deviation  # straight lines through the cube do not fit


# ---------------------------------------------------------------- stability guard


def largest_stable_dt(make, bound, steps=2000):
    """Bisection for the largest dt that runs `steps` steps without blowing up (1% resolution)."""
    low, high = 0.5 * bound, 1.5 * bound
    while high - low > 0.005 * bound:
        dt = 0.5 * (low + high)
        try:
            make(dt).advance(steps)
            low = dt
        except BlowUpError:
            high = dt
    return low


@pytest.mark.parametrize("discretization", ["subdivision", "p1"])
@pytest.mark.parametrize("mass_corrections", [0, 2])
def test_telegraph_stable_dt_matches_its_bound_and_the_guard_fires_beyond(discretization, mass_corrections, rng):
    op = sphere_operator(1.0, 2, discretization=discretization)
    gamma = 2.0
    c0 = 1e-3 * rng.normal(size=op.n_vertices)  # every mode, the highest included

    def make(dt, **kwargs):
        return Telegraph(op, gamma, 0.001, c0=c0, dt=dt, mass_corrections=mass_corrections, check_every=100, **kwargs)

    # the bound from a dense eigenvalue of W_p K (W_0 = M⁻¹), not from the stepper's power iteration
    G = np.diag(1 / op.mass())
    W, term = G.copy(), G.copy()
    for _ in range(mass_corrections):
        term = term - G @ (op.mass_matrix() @ term)
        W += term
    largest = np.max(np.linalg.eigvals(W @ op.stiffness_matrix().toarray()).real)
    predicted = 2 / (gamma * math.sqrt(largest))
    reference = make(None)
    assert reference.stable_dt == pytest.approx(predicted, rel=2e-3)
    assert reference.dt == pytest.approx(0.9 * reference.stable_dt)
    measured = largest_stable_dt(lambda dt: make(dt, check_dt=False), predicted)
    assert measured == pytest.approx(predicted, rel=0.1)  # measured: within 1%
    with pytest.raises(ValueError, match=r"dt = .* exceeds the stability bound .*: use dt <= .*, e.g. dt = "):
        make(1.05 * reference.stable_dt)


def test_fhn_explicit_stable_dt_matches_its_bound_and_the_guard_fires_beyond(rng):
    op = sphere_operator(1.0, 2)
    gamma = 3.0  # γ² λ_max >> L_f, so the diffusive limit is what is measured
    c0 = 1e-3 * rng.normal(size=op.n_vertices)

    def make(dt, **kwargs):
        return FitzHughNagumo(op, gamma, c0=c0, dt=dt, check_every=100, **kwargs)

    largest = sla.eigsh(op.stiffness_matrix(), k=1, M=sp.diags(op.mass()), which="LA", return_eigenvectors=False)[0]
    predicted = 2 / (gamma**2 * largest + 1.01)  # L_f = 1 - ν for ν = -0.01
    assert make(None).stable_dt == pytest.approx(predicted, rel=2e-3)
    measured = largest_stable_dt(lambda dt: make(dt, check_dt=False), predicted)
    assert measured == pytest.approx(predicted, rel=0.1)
    with pytest.raises(ValueError, match=r"exceeds the stability bound"):
        make(1.05 * predicted)
    with pytest.raises(ValueError, match=r"dt < 2 / L_f"):
        make(2.5, scheme="imex")  # IMEX lifts the diffusive limit, not the reaction's 2 / L_f


def test_changing_dt_keeps_the_leapfrog_second_order():
    """Step 1/N to t = 1, then 1/(2N) to t = 2, against a run at 1/(40N): with the half-step
    velocity re-centred the error falls 4× when N doubles; left as it was, only 2×."""
    op = LaplaceBeltrami(icosphere(1.0, 2), **F64)
    c0 = op.control_values(op.points()[:, 2] ** 2)  # the l = 0 and l = 2 modes

    def switched(n, recentre):
        wave = Telegraph(op, 1.0, 0.001, c0=c0, dt=1.0 / n).advance(n)
        wave.change_dt(0.5 / n, recentre=recentre)
        return wave.advance(2 * n).concentration()

    def error(n, recentre):
        reference = Telegraph(op, 1.0, 0.001, c0=c0, dt=1.0 / (40 * n)).advance(80 * n).concentration()
        return np.abs(switched(n, recentre) - reference).max()

    assert error(20, True) / error(40, True) == pytest.approx(4.0, rel=0.1)
    assert error(20, False) / error(40, False) == pytest.approx(2.0, rel=0.1)
    wave = Telegraph(op, 1.0, 0.001, c0=c0)
    with pytest.raises(TimeStepError, match="exceeds the stability bound"):
        wave.change_dt(1.1 * wave.stable_dt)


def test_blow_up_stops_with_a_clear_error_and_keeps_the_last_finite_state(rng):
    op = sphere_operator(1.0, 2)
    c0 = 1e-3 * rng.normal(size=op.n_vertices)
    bound = Telegraph(op, 1.0, c0=c0).stable_dt
    wave = Telegraph(op, 1.0, c0=c0, dt=1.2 * bound, check_dt=False, check_every=25)
    with pytest.raises(BlowUpError, match=r"blew up between t = .* state is restored") as error:
        wave.advance(1000)
    assert np.all(np.isfinite(wave.concentration())) and np.all(np.isfinite(wave.velocity()))
    assert error.value.steps == wave.steps and error.value.time == wave.time
    assert np.abs(wave.concentration()).max() <= wave.blowup_limit


# ---------------------------------------------------------------- FHN flip-flop past the bound (docs/theory/scenes.md)


def flip_flags(values):
    """Run flip_kernel over a sequence of one vertex's values c^0, c^1, ...: the flag after each step."""
    import warp as wp

    c = wp.array(values[:1], dtype=wp.float64, device="cpu")
    previous = wp.clone(c)
    increment, earlier = wp.zeros(1, dtype=wp.float64, device="cpu"), wp.zeros(1, dtype=wp.float64, device="cpu")
    streak, flag = wp.zeros(1, dtype=wp.int32, device="cpu"), wp.zeros(1, dtype=wp.int32, device="cpu")
    flags = []
    for value in values[1:]:
        c.fill_(value)
        wp.launch(flip_kernel, dim=1, inputs=[c, wp.float64(FLIP_FLOOR), wp.float64(FLIP_HOLD), FLIP_STEPS],
                  outputs=[previous, increment, earlier, streak, flag], device="cpu")  # fmt: skip
        flags.append(int(flag.numpy()[0]))
    return flags


def test_flip_detector_counts_only_lasting_sign_flips_above_the_floor():
    """c^n = 1 + a_n (-1)^n: a steady or growing flip-flop sets the flag when its increment has
    flipped sign FLIP_STEPS times in a row (step FLIP_STEPS + 1); the alternation of a stable dt
    (decaying by 0.9 per step), one below the floor (round-off) and a smooth rise never do."""
    n = np.arange(4 * FLIP_STEPS)
    steady = flip_flags(1 + 0.05 * (-1.0) ** n)
    assert steady.index(FLIP_FLOP) == FLIP_STEPS and set(steady[FLIP_STEPS:]) == {FLIP_FLOP}
    assert flip_flags(1 + 0.01 * (-1.01) ** n).index(FLIP_FLOP) == FLIP_STEPS
    assert not any(flip_flags(1 + 0.05 * (-0.9) ** n))
    assert not any(flip_flags(1 + 0.2 * FLIP_FLOOR * (-1.0) ** n))
    assert not any(flip_flags(np.tanh(0.1 * n) + 1e-12 * (-1.0) ** n))


def excited_fhn(op, ratio, scheme="explicit"):
    """FHN at its kinetic fixed point c = 1 (ε = 0, so w stays 0; γ = 1) plus noise in [0, 1e-3],
    dt = ratio × the bound, which is sharp there (f'(1) = ν - 1 = -L_f): the stability
    benchmark's "excited" state."""
    c0 = 1 + 1e-3 * np.random.default_rng(7).uniform(0.0, 1.0, op.n_vertices)
    bound = FitzHughNagumo(op, 1.0, epsilon=0.0, c0=c0, scheme=scheme).stable_dt
    return FitzHughNagumo(op, 1.0, epsilon=0.0, c0=c0, dt=ratio * bound, scheme=scheme, check_dt=False)


def host_euler(op, c0, dt, steps, nu=-0.01):
    """Explicit Euler of that FHN (γ = 1, w = 0) on the host: c += dt (f(c) - M⁻¹K c); every c^n."""
    K, m = op.stiffness_matrix(), op.mass()
    history = [c0]
    for _ in range(steps):
        c = history[-1]
        history.append(c + dt * (c * (1 - c) * (c - nu) - (K @ c) / m))
    return np.array(history)


def test_fhn_flip_flop_past_the_bound_stops_with_an_oscillation_error():
    """Explicit FHN at 1.01 × its bound does not blow up: the top mode grows until the cubic holds it
    in a bounded period-2 flip-flop (host Euler here: 5000 steps, |c| < 2, no NaN, far inside
    blowup_limit, so the runaway check alone never fires). The flip detector stops the stepper with
    OscillationError, a BlowUpError, its state restored to the last good check of the same run."""
    op = sphere_operator(1.0, 2)
    wave = excited_fhn(op, 1.01)
    history = host_euler(op, wave.concentration(), wave.dt, 5000)
    assert np.all(np.isfinite(history)) and np.abs(history).max() < 2 and wave.blowup_limit > 1e5
    increments = np.diff(history[-100:], axis=0)
    flipping = np.all(increments[1:] * increments[:-1] < 0, axis=0)
    assert flipping.any() and np.abs(increments[:, flipping]).min() > 0.1  # settled, sign flips every step
    with pytest.raises(OscillationError, match=r"period-2 flip-flop between t = .* dt = .* stability bound .* \(dt=None in Python; --set dt=auto") as error:
        wave.advance(5000)
    assert isinstance(error.value, BlowUpError) and error.value.steps == wave.steps and error.value.time == wave.time
    assert wave.steps % wave.check_every == 0 and wave.steps < 5000
    np.testing.assert_allclose(wave.concentration(), history[wave.steps], atol=1e-9)
    np.testing.assert_array_equal(wave.inhibitor(), 0.0)


def test_fhn_imex_flip_flop_past_its_reaction_bound_stops_too():
    """IMEX past 2 / L_f: the uniform mode (untouched by implicit diffusion) flips at c = 1."""
    wave = excited_fhn(sphere_operator(1.0, 2), 1.01, "imex")
    with pytest.raises(OscillationError, match=r"imex Euler fell into a period-2 flip-flop .*\(dt < 2 / L_f\)"):
        wave.advance(2000)
    assert np.abs(wave.concentration() - 1).max() < 0.5


@pytest.mark.parametrize("scheme", ["explicit", "imex"])
def test_fhn_below_the_bound_runs_long_without_a_flip_flop(scheme):
    """The same state at 0.9 × the bound: deviations alternate but decay, for 5000 steps."""
    wave = excited_fhn(sphere_operator(1.0, 2), 0.9, scheme).advance(5000)
    assert np.abs(wave.concentration() - 1).max() < 1e-9


@pytest.mark.parametrize("scheme", ["explicit", "imex"])
def test_fhn_pulses_at_the_default_dt_never_trip_the_flip_detector(scheme):
    """the paper's parameters, float32, dt = None (0.9 × the bound), a narrow pulse (control values up to
    1.2) on a level-2 sphere: 2000 steps, about 7 kinetic periods of pulses from the pacemaker."""
    op = LaplaceBeltrami(icosphere(1.0, 2), device="cpu", dtype="float32")
    c0, _ = gaussian_pulse(op, 0, 0.3, gamma=0.2)
    wave = FitzHughNagumo(op, c0=c0, scheme=scheme)
    peaks = [wave.advance(20).concentration().max() for _ in range(100)]
    assert max(peaks) > 0.9 and min(peaks) < 0.1  # excited and recovered, not stopped


# ---------------------------------------------------------------- FitzHugh–Nagumo pulse speed


def fhn_speed_1d(gamma, nu, kappa, epsilon, dx=0.04, length=40.0, t_end=60.0):
    """Front speed of the 1-D FHN pulse: explicit finite differences, Neumann ends, the front
    (c = ½ crossing) tracked over the second half of the run, after the start-up transient."""
    x = np.arange(0.0, length + dx / 2, dx)
    c, w = np.exp(-(x**2) / (2 * 0.5**2)), np.zeros_like(x)
    dt = 0.2 * dx * dx / gamma**2
    times, fronts = [], []
    for k in range(int(t_end / dt)):
        laplacian = np.empty_like(c)
        laplacian[1:-1] = c[2:] - 2 * c[1:-1] + c[:-2]
        laplacian[0], laplacian[-1] = 2 * (c[1] - c[0]), 2 * (c[-2] - c[-1])
        c, w = c + dt * (gamma**2 * laplacian / dx**2 + c * (1 - c) * (c - nu) - w), w + dt * epsilon * (c - kappa * w)
        if k % 50 == 0 and k * dt > t_end / 2:
            i = np.flatnonzero((c[:-1] >= 0.5) & (c[1:] < 0.5))[-1]
            fronts.append(x[i] + dx * (c[i] - 0.5) / (c[i] - c[i + 1]))
            times.append(k * dt)
    return np.polyfit(times, fronts, 1)[0]


def latitude_arrival(theta, speed, radius, diffusion):
    """Arrival time at polar angle θ (up to a constant) of a front whose normal speed is
    V = v - D κ_g, κ_g = cot θ / R the geodesic curvature of the latitude circle: ∫ R dθ / V,
    in closed form with v sin θ - a cos θ = ρ sin(θ - φ), a = D / R."""
    a = diffusion / radius
    rho, phi = math.hypot(speed, a), math.atan2(a, speed)
    return radius * (theta * math.cos(phi) + math.sin(phi) * np.log(np.sin(theta - phi))) / rho


def test_fhn_pulse_speed_on_a_large_sphere_matches_the_1d_pulse():
    """docs/theory/chemistry.md parameters; R = 6 (30 front widths), subdivision, lumped mass, level 5."""
    gamma, nu, kappa, epsilon, radius = 0.2, -0.01, 1e-4, 0.005, 6.0
    speed_1d = fhn_speed_1d(gamma, nu, kappa, epsilon)
    op = sphere_operator(radius, 5)
    pole = np.array([0.0, 0.0, radius])
    c0, _ = gaussian_pulse(op, pole, 0.5 / radius, gamma=gamma, radius=radius, distance="arc")
    wave = FitzHughNagumo(op, gamma, nu, kappa, epsilon, c0=c0, dt=0.05)
    theta = np.arccos(np.clip(op.points() @ pole / radius**2, -1, 1))
    probes = (theta > np.pi / 4) & (theta < 3 * np.pi / 4)
    arrival = np.full(probes.sum(), np.nan)
    previous, t_previous = op.field_values(wave.concentration())[probes], 0.0
    while np.isnan(arrival).any():
        wave.advance(1)
        current = op.field_values(wave.concentration())[probes]
        crossing = np.isnan(arrival) & (previous < 0.5) & (current >= 0.5)
        arrival[crossing] = t_previous + (wave.time - t_previous) * (0.5 - previous[crossing]) / (current - previous)[crossing]
        previous, t_previous = current, wave.time
        assert wave.time < 2 * radius * np.pi / speed_1d, "the front stalled"

    def misfit(speed):
        model = latitude_arrival(theta[probes], speed, radius, gamma**2)
        return np.sum((arrival - model - np.mean(arrival - model)) ** 2)

    speed = minimize_scalar(misfit, bounds=(0.5 * speed_1d, 1.5 * speed_1d), method="bounded").x
    assert speed == pytest.approx(speed_1d, rel=0.03)  # measured -1.8%


def test_fhn_imex_lifts_the_diffusive_limit_and_agrees_with_explicit_steps():
    op = sphere_operator(3.0, 3)
    gamma = 1.0
    c0, _ = gaussian_pulse(op, 0, 0.2, gamma=gamma)
    explicit = FitzHughNagumo(op, gamma, c0=c0, dt=0.01).run_until(8.0)
    imex = FitzHughNagumo(op, gamma, c0=c0, dt=0.01, scheme="imex").run_until(8.0)
    assert np.abs(imex.concentration() - explicit.concentration()).max() < 0.01
    dt = 7 * explicit.stable_dt  # past the explicit (diffusive) bound, within IMEX's 2 / L_f
    plain = FitzHughNagumo(op, gamma, c0=c0, dt=dt, scheme="imex", capture=False).run_until(30.0)
    captured = FitzHughNagumo(op, gamma, c0=c0, dt=dt, scheme="imex").run_until(30.0)
    np.testing.assert_allclose(captured.concentration(), plain.concentration(), atol=1e-12)
    assert np.all(np.abs(plain.concentration()) < 1.5)


# ---------------------------------------------------------------- initial conditions and input checks


def test_gaussian_pulse_is_outgoing_and_interpolates_the_profile():
    op = sphere_operator(2.0, 3)
    sigma, gamma = 0.3, 0.7
    c0, v0 = gaussian_pulse(op, 5, sigma, gamma=gamma, radius=2.0, distance="arc")
    origin = op.points()[5]
    # great-circle distance by atan2 (arccos of the cosine loses √ε at the origin itself: 3e-7 in v0)
    s = 2.0 * np.arctan2(np.linalg.norm(np.cross(op.points(), origin), axis=1), op.points() @ origin)
    np.testing.assert_allclose(op.field_values(c0), np.exp(-((s / 2.0) ** 2) / (2 * sigma**2)), atol=1e-12)
    np.testing.assert_allclose(op.field_values(v0), gamma * s / (4.0 * sigma**2) * op.field_values(c0), atol=1e-12)
    assert op.mass() @ v0 > 0  # the total concentration rises


def test_steady_front_profile_and_outgoing_velocity():
    radius, k, delta, gamma = 1.0, 12.0, 0.6, 0.5
    op = sphere_operator(radius, 3)
    origin = 7
    axis = op.points()[origin] / np.linalg.norm(op.points()[origin])
    c0, v0 = steady_front(op, origin, k=k, delta=delta, gamma=gamma, axis=axis)
    height = (op.points()[origin] - op.points()) @ axis  # >= 0 on the sphere
    profile = (1 + math.exp(-delta * k)) / (1 + np.exp(k * (height - delta)))
    np.testing.assert_allclose(op.field_values(c0), profile, atol=1e-12)
    assert op.field_values(c0)[origin] == pytest.approx(1.0)
    # on a sphere |∇z| = sin θ, so c_t = -γ dc/ds exactly as for the profile in arc length
    theta = np.arccos(np.clip(op.points() @ axis / radius, -1, 1))
    dc_ds = -(1 + math.exp(-delta * k)) * k * np.exp(k * (height - delta)) / (1 + np.exp(k * (height - delta))) ** 2 * np.sin(theta)
    np.testing.assert_allclose(op.field_values(v0), -gamma * dc_ds, atol=2e-2 * gamma * k)  # nodal normals: O(h²)
    assert np.all(op.field_values(v0) >= -1e-9)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda op: Telegraph(op, 1.0, c0=np.ones(3)), r"c0 must have shape \(162,\)"),
        (lambda op: Telegraph(op, 1.0, c0=np.zeros(162), v0=np.full(162, np.inf)), r"v0\[0\] is not finite"),
        (lambda op: Telegraph(op, -1.0, c0=np.zeros(162)), "gamma must be a positive"),
        (lambda op: Telegraph(op, 1.0, alpha=-0.1, c0=np.zeros(162)), "alpha must be >= 0"),
        (lambda op: Telegraph(op, 1.0, c0=np.zeros(162), dt=0.0), "dt must be a positive"),
        (lambda op: Telegraph(op, 1.0, c0=np.zeros(162), safety=1.5), r"safety must lie in \(0, 1\]"),
        (lambda op: Telegraph(op, 1.0, c0=np.zeros(162), mass_corrections=-1), "mass_corrections must be an integer"),
        (lambda op: Telegraph(op.mesh, 1.0, c0=np.zeros(162)), "operator must be a wavewarp.LaplaceBeltrami"),
        (lambda op: FitzHughNagumo(op, c0=np.zeros(162), scheme="rk4"), "scheme must be one of explicit, heun, imex"),
        (lambda op: FitzHughNagumo(op, c0=np.zeros(162), scheme="imex", mass_corrections=1), "lumped mass"),
        (lambda op: gaussian_pulse(op, 1000, 0.1, gamma=1.0), r"origin vertex must lie in \[0, 162\)"),
        (lambda op: gaussian_pulse(op, 0, 0.1, gamma=1.0, distance="manhattan"), "distance must be"),
        (lambda op: Telegraph(op, 1.0, c0=np.zeros(162)).advance(-1), "steps must be an integer >= 0"),
    ],
)
def test_bad_input_names_the_argument(make, message):
    with pytest.raises(ValueError, match=message):
        make(sphere_operator(1.0, 2))


def test_a_moving_surface_refreshes_the_bound():
    """update(x) (deformation-sensitive waves): automatic dt follows the surface, a fixed dt past
    the new bound is refused."""
    mesh = icosphere(1.0, 2)
    op = LaplaceBeltrami(mesh, **F64)
    c0, v0 = gaussian_pulse(op, 0, 0.4, gamma=1.0)
    automatic = Telegraph(op, 1.0, c0=c0, v0=v0)
    fixed = Telegraph(op, 1.0, c0=c0, v0=v0, dt=0.8 * automatic.stable_dt)
    bound = automatic.stable_dt
    op.update(0.5 * mesh.vertices)  # λ_max × 4: the bound halves
    automatic.advance(3)
    assert automatic.stable_dt == pytest.approx(0.5 * bound, rel=1e-3)
    assert automatic.dt == pytest.approx(0.9 * automatic.stable_dt)
    with pytest.raises(ValueError, match="exceeds the stability bound"):
        fixed.advance(1)


def test_float32_waves_track_float64(device):
    results = {}
    for dtype in ("float32", "float64"):
        op = LaplaceBeltrami(icosphere(1.0, 2), device=device, dtype=dtype)
        c0, v0 = gaussian_pulse(op, 0, 0.4, gamma=1.0)
        wave = Telegraph(op, 1.0, c0=c0, v0=v0, dt=0.05).advance(40)
        fhn = FitzHughNagumo(op, 1.0, c0=c0, dt=0.01).advance(100)
        fhn_imex = FitzHughNagumo(op, 1.0, c0=c0, dt=0.05, scheme="imex").advance(20)
        results[dtype] = [wave.concentration(), fhn.concentration(), fhn_imex.concentration()]
    for single, double in zip(results["float32"], results["float64"]):
        assert np.abs(single - double).max() <= 1e-4 * np.abs(double).max()

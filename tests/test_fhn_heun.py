"""The FitzHugh–Nagumo Heun (RK2) step: second order in dt against an independent solve of the same semi-discrete
system, first order for Euler beside it, and the chemical's amount accounted to round-off."""

import math

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.integrate import solve_ivp

from wavewarp.initial import gaussian_pulse
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import icosphere
from wavewarp.waves import FitzHughNagumo, TimeStepError

R, GAMMA, NU, KAPPA, EPSILON = 10.0, 0.2, -0.01, 1e-4, 0.005
T_END, STEPS = 6.0, (15, 30, 60)  # dt = 0.4, 0.2, 0.1: inside the level-2 bound (about 1.9)


def pulse(op):
    c0, _ = gaussian_pulse(op, 0, 0.4, gamma=GAMMA, radius=R)
    return np.asarray(c0, dtype=np.float64)


def reference(op, c0) -> np.ndarray:
    """c(T_END) of the lumped semi-discrete system ċ = -γ² M⁻¹K c + f(c) - w, ẇ = ε (c - κ w), by scipy's
    adaptive Runge–Kutta at a tolerance far below the schemes' errors."""
    K = op.stiffness_matrix()
    inverse_mass = sp.diags(1.0 / op.mass())
    diffusion = (inverse_mass @ K).tocsr()
    n = len(c0)

    def rates(_, y):
        c, w = y[:n], y[n:]
        return np.concatenate([-GAMMA**2 * (diffusion @ c) + c * (1 - c) * (c - NU) - w, EPSILON * (c - KAPPA * w)])

    solution = solve_ivp(rates, (0.0, T_END), np.concatenate([c0, np.zeros(n)]), method="DOP853", rtol=1e-12,
                         atol=1e-14)
    assert solution.success
    return solution.y[:n, -1]


def final(op, c0, scheme, steps, corrections=0) -> FitzHughNagumo:
    wave = FitzHughNagumo(op, GAMMA, NU, KAPPA, EPSILON, c0=c0, dt=T_END / steps, scheme=scheme,
                          mass_corrections=corrections)
    wave.advance(steps)
    return wave


def test_heun_is_second_order_in_dt_and_euler_first(device):
    """Errors at T = 6 against the independent solve, dt halved twice: Heun's fall 4× a halving (order 2 within
    0.2), Euler's 2× (order 1 within 0.2), and Heun at the coarsest dt beats Euler at the finest."""
    op = LaplaceBeltrami(icosphere(R, 2), device=device, dtype="float64")
    c0 = pulse(op)
    exact = reference(op, c0)
    errors = {scheme: [np.abs(final(op, c0, scheme, n).concentration() - exact).max() for n in STEPS]
              for scheme in ("heun", "explicit")}
    orders = {scheme: [math.log2(e[k] / e[k + 1]) for k in range(2)] for scheme, e in errors.items()}
    assert all(abs(order - 2) < 0.2 for order in orders["heun"]), (errors, orders)
    assert all(abs(order - 1) < 0.2 for order in orders["explicit"]), (errors, orders)
    assert errors["heun"][0] < errors["explicit"][-1], errors


@pytest.mark.parametrize("corrections", [0, 2])
def test_heun_accounts_the_chemical_to_round_off(corrections, device):
    """C(t) = C(0) + produced(): the two stages' reaction amounts are what the step adds (diffusion adds none)."""
    op = LaplaceBeltrami(icosphere(R, 2), device=device, dtype="float64")
    c0 = pulse(op)
    start = float(op.mass() @ c0)
    wave = final(op, c0, "heun", 40, corrections)
    assert wave.produced() != 0.0
    assert abs(wave.total() - start - wave.produced()) < 1e-12 * float(op.mass() @ np.abs(c0))


def test_heun_keeps_eulers_stability_bound(device):
    """Heun's stability interval on the real axis is Euler's: the same automatic step and the same refusal."""
    op = LaplaceBeltrami(icosphere(R, 2), device=device, dtype="float64")
    c0 = pulse(op)
    euler = FitzHughNagumo(op, GAMMA, NU, KAPPA, EPSILON, c0=c0)
    heun = FitzHughNagumo(op, GAMMA, NU, KAPPA, EPSILON, c0=c0, scheme="heun")
    assert heun.dt == pytest.approx(euler.dt, rel=1e-4)  # the bound's λ_max is iterated to 1e-5
    assert heun.solver.scheme == "FitzHugh–Nagumo Heun (RK2)"
    with pytest.raises(TimeStepError, match="Heun"):
        FitzHughNagumo(op, GAMMA, NU, KAPPA, EPSILON, c0=c0, scheme="heun", dt=1.2 * euler.dt / 0.9)

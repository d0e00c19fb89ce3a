"""Batched quasi-static waves (wavewarp/quasistatic_batch.py, issue 28): buckling-modes worlds that
differ in AI, h, AC, μV and seed relax together. The reference for each world is its own single run,
computed here: in deterministic float64 on the CPU the two agree bit for bit. On CUDA they agree to
round-off (2e-14 R on an H200; a batch repeated is bitwise equal): some sum groups a world's terms
differently beside other worlds. The suspects are the relaxation's atomic sums in Warp's run-to-run
deterministic mode (walker batches, which do not relax, are bitwise on CUDA). A world that fails (its
wave blows up, its surface lowers the stability bound below dt, or its relaxation fails) stops alone."""

import functools

import numpy as np
import pytest

from wavewarp.device import set_deterministic
from wavewarp.driver import simulate
from wavewarp.parameters import resolve
from wavewarp.scenes import buckling_modes as scene

QUIET = lambda message: None  # noqa: E731
SMALL = {"level": 2, "frames": 3, "t_end": 3.0, "dtype": "float64", "adaptive_dt": False, "self_contact": False,
         "dt": 0.05, "relax_every": 4, "relax_iterations": 300}  # fmt: skip


SPOIL_BUDGET = 100  # CG iterations per relaxation in the spoiling tests


def assert_same(actual, expected, device):
    """Bitwise on the CPU; to round-off (1e-12 relative) on CUDA."""
    if device == "cpu":
        np.testing.assert_array_equal(actual, expected)
    else:
        np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-12)


def same_measurements(actual: dict, expected: dict, device) -> bool:
    if device == "cpu":
        return actual == expected
    return actual.keys() == expected.keys() and all(
        a == pytest.approx(e, rel=1e-9, abs=1e-12) if isinstance(e, float) else a == e
        for a, e in zip(actual.values(), expected.values()))  # fmt: skip


@pytest.fixture
def deterministic():
    set_deterministic(True)
    yield
    set_deterministic(False)


def worlds(**shared):
    """Two worlds apart in AI, h, AC, μV (and, by the caller, the seed)."""
    own = [{"AI": 10.5, "thickness": 0.5}, {"AI": 13.5, "thickness": 0.25, "AC": 0.1, "mu_v": 0.5}]
    return [resolve(scene.Parameters, None, [f"{k}={v}" for k, v in {**SMALL, **shared, **o}.items()]) for o in own]


def test_each_world_of_a_quasi_static_batch_equals_its_single_run_bit_for_bit(deterministic, device):
    ps, seeds = worlds(), [0, 1]
    batch = scene.build_batch(ps, seeds=seeds, device=device, report=QUIET)
    results = batch.run()
    x, c, n = batch.coupled.positions(), batch.wave.concentration(), batch.vertices
    for w, (p, seed) in enumerate(zip(ps, seeds)):
        run = scene.build(p, device=device, seed=seed, report=QUIET)
        outcome = simulate(run, [])
        assert outcome.failure is None and results[w]["status"] == "done"
        assert_same(x[w * n:(w + 1) * n], run.coupled.positions(), device)
        assert_same(c[w * n:(w + 1) * n], run.wave.concentration(), device)
        assert results[w]["frames"] == run.frames + 1
        assert same_measurements(results[w]["measurements"], outcome.measurements, device)
    assert not np.array_equal(x[:n], x[n:])  # the worlds did differ


def shrink(batch, n):
    """World 1 shrunk a hundredfold about its centre: its wave's stability bound falls a hundredfold,
    below dt (the limit surface smooths away any one vertex's move)."""
    x = batch.coupled.positions()
    x[n:] = x[n:].mean(axis=0) + 0.01 * (x[n:] - x[n:].mean(axis=0))
    batch.coupled.restore(x)


def turn_inside_out(batch, n):
    """World 1 mirrored through its equator: an everted sphere, which its relaxation cannot turn back
    within the budget."""
    x = batch.coupled.positions()
    x[n:, 2] *= -1.0
    batch.coupled.state.set("x", x)


def poison_positions(batch, n):
    x = batch.coupled.positions()
    x[n + 5] = np.nan
    batch.coupled.state.set("x", x)


def poison_rate(batch, n):
    rate = batch.coupled.state.numpy("rate")
    rate[n + 5] = np.nan
    batch.coupled.state.set("rate", rate)


def spoil_worlds():
    return worlds(accept_unconverged=False, relax_iterations=SPOIL_BUDGET, dt=0.5, relax_every=2)


@functools.cache
def clean_batches(device):
    """The spoiling tests' batch run without spoiling, once per device (inside a deterministic test)."""
    clean = scene.build_batch(spoil_worlds(), seeds=[0, 1], device=device, report=QUIET)
    clean.run()
    return clean


@pytest.mark.parametrize("spoil, message", [(poison_rate, "blew up"), (turn_inside_out, "relax stopped in world 1"),
                                            (shrink, "exceeds the stability bound"),
                                            (poison_positions, "the energy is not finite")])  # fmt: skip
def test_a_quasi_static_world_that_fails_stops_alone(deterministic, device, spoil, message):
    """World 1 spoiled after the first frame (its wave's rate NaN: a blow-up; its positions mirrored: a
    relaxation over its budget; its surface shrunk: dt above its bound; a position NaN: a relaxation
    whose energy is not finite) stops with that error, its
    frozen state the one it had when the failing step began; world 0 ends as in a batch without
    the spoiling (dt = 0.5, a sixth of the bound: a clean batch takes at most 68 of the iterations)."""
    ps, seeds = spoil_worlds(), [0, 1]
    clean = clean_batches(device)
    batch = scene.build_batch(ps, seeds=seeds, device=device, report=QUIET)
    n, kept = batch.vertices, {}

    def spoil_after_first(frames):
        if frames == 1:
            spoil(batch, n)
            kept.update(x=batch.coupled.positions()[n:], c=batch.wave.concentration()[n:], time=batch.time)

    results = batch.run(progress=spoil_after_first)
    assert results[0]["status"] == "done" and results[0]["frames"] == batch.frames + 1
    assert results[1]["status"] == "stopped" and message in results[1]["stopped"] and results[1]["frames"] == 2
    assert_same(batch.coupled.positions()[:n], clean.coupled.positions()[:n], device)
    assert_same(batch.wave.concentration()[:n], clean.wave.concentration()[:n], device)
    frozen = batch.coupled.frozen(1)
    np.testing.assert_array_equal(frozen["x"], kept["x"])
    np.testing.assert_array_equal(frozen["c"], kept["c"])
    assert kept["time"] <= results[1]["measurements"]["time"] < batch.time
    assert batch.coupled.frozen(0) is None


def test_a_quasi_static_batch_refuses_the_adaptive_step_and_self_contact():
    for switch in ("adaptive_dt", "self_contact"):
        ps = worlds(**{switch: True})
        with pytest.raises(ValueError, match=f"--set {switch}=false"):
            scene.build_batch(ps, seeds=[0, 0], device="cpu", report=QUIET)


def test_accept_unconverged_does_not_take_positions_that_are_not_finite():
    """accept_unconverged takes a relaxation that spent its budget, never one from NaN positions
    (max |F| skips NaN: without the energy's check it would read as converged)."""
    from wavewarp.relax import RelaxationError

    run = scene.build(worlds(accept_unconverged=True)[0], device="cpu", report=QUIET)
    x = run.coupled.positions()
    x[5] = np.nan
    run.coupled.state.set("x", x)
    with pytest.raises(RelaxationError, match="the energy is not finite"):
        run.coupled.step()

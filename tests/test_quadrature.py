from math import factorial

import numpy as np
import pytest

from wavewarp.quadrature import triangle_rule

DEGREE = {"3": 2, "6": 4, "7": 5, "12": 6, "3x4": 2, "3x16": 2, "12x64": 6}


def exact_monomial(i, j):
    """∫ v^i w^j over the unit parameter triangle."""
    return factorial(i) * factorial(j) / factorial(i + j + 2)


@pytest.mark.parametrize("rule", DEGREE)
def test_rule_integrates_polynomials_of_its_degree_exactly(rule):
    points, weights = triangle_rule(rule)
    assert np.all(weights > 0)
    assert np.all(points >= 0) and np.all(points.sum(axis=1) <= 1)
    for i in range(DEGREE[rule] + 1):
        for j in range(DEGREE[rule] + 1 - i):
            value = np.sum(weights * points[:, 0] ** i * points[:, 1] ** j)
            assert value == pytest.approx(exact_monomial(i, j), rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("rule", ["3", "6", "7", "12"])
def test_rule_is_not_exact_one_degree_higher(rule):
    points, weights = triangle_rule(rule)
    d = DEGREE[rule] + 1
    errors = [
        abs(np.sum(weights * points[:, 0] ** i * points[:, 1] ** (d - i)) - exact_monomial(i, d - i))
        for i in range(d + 1)
    ]
    assert max(errors) > 1e-8


def test_composite_rule_converges_on_a_smooth_function():
    exact = 1.0  # ∫∫_{v+w<=1} exp(v + w) = ∫_0^1 s e^s ds
    errors = []
    for rule in ("3", "3x4", "3x16", "3x64"):
        points, weights = triangle_rule(rule)
        errors.append(abs(np.sum(weights * np.exp(points.sum(axis=1))) - exact))
    assert all(e1 < e0 / 3.5 for e0, e1 in zip(errors, errors[1:]))


@pytest.mark.parametrize("name", ["2", "3x5", "x4", "13x4", "abc"])
def test_unknown_rule_is_named(name):
    with pytest.raises(ValueError, match="quadrature rule"):
        triangle_rule(name)

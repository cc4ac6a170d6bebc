"""C-DNF parameters, activation functions and lateral kernels (docs/EQUATIONS.md)."""
import math

import numpy as np
import pytest

from cdnf_ti.params import CDNFParams, contrast_kernel, dog_kernel, resting_level, theta, vartheta


def test_contrast_kernel_sums_to_one():
    assert contrast_kernel(1.0).sum() == pytest.approx(1.0, abs=1e-15)


def test_contrast_kernel_is_normalised_gaussian_of_sigma_c():
    w = contrast_kernel(1.0)
    assert w.shape == (3, 3)
    assert w[0, 1] / w[1, 1] == pytest.approx(math.exp(-0.5))
    assert w[0, 0] / w[1, 1] == pytest.approx(math.exp(-1.0))
    z = 1 + 4 * math.exp(-0.5) + 4 * math.exp(-1.0)
    assert w[1, 1] == pytest.approx(1 / z)


def test_dog_kernel_is_7x7_for_default_sigmas():
    p = CDNFParams()
    assert p.sigma_2 == pytest.approx(1.0)
    assert p.radius_s == 3
    assert dog_kernel(p).shape == (7, 7)


@pytest.mark.parametrize("dx,dy", [(0, 0), (1, 0), (0, 1), (1, 1), (2, 1), (3, 3), (0, 3)])
def test_dog_kernel_values_follow_the_formula(dx, dy):
    w = dog_kernel(CDNFParams())
    r2 = dx * dx + dy * dy
    expected = 1.5 * math.exp(-r2 / (2 * (1 / 3) ** 2)) - 0.5 * math.exp(-r2 / 2.0)
    assert w[3 + dy, 3 + dx] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert w[3 - dy, 3 - dx] == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_dog_kernel_centre_is_A_minus_B_and_not_normalised():
    w = dog_kernel(CDNFParams())
    assert w[3, 3] == pytest.approx(1.0)
    assert abs(w.sum() - 1.0) > 0.5


def test_vartheta_is_tanh_half_and_theta_of_one_is_one():
    a = np.linspace(-5, 5, 101)
    assert np.allclose(vartheta(a), 2 / (1 + np.exp(-a)) - 1, atol=1e-14)
    assert theta(1.0) == pytest.approx(1.0, abs=1e-15)
    assert np.allclose(theta(a), np.tanh(a) * (math.e**2 + 1) / (math.e**2 - 1))


def test_resting_level_solves_the_uniform_field_equation():
    u = resting_level(0.2, 1.0)
    assert u == pytest.approx(-0.2 + math.tanh(u / 2), abs=1e-14)
    assert u < 0


def test_threshold_is_half_plus_epsilon():
    assert CDNFParams().threshold == pytest.approx(0.506)


@pytest.mark.parametrize(
    "change,fragment",
    [
        ({"tol": -1e-5}, "tol"),
        ({"tol": 0.0}, "tol"),
        ({"sigma_c": 0.0}, "sigma_c"),
        ({"sigma_1": -1.0}, "sigma_1"),
        ({"steps_per_launch": 0}, "steps_per_launch"),
        ({"steps_per_launch": 33}, "steps_per_launch"),
        ({"sigma_2": 0.0}, "sigma_2"),
        ({"max_iter": 0}, "max_iter"),
        ({"damping": 0.0}, "damping"),
        ({"damping": 1.5}, "damping"),
        ({"border": "wrap"}, "border"),
        ({"epsilon": -0.1}, "epsilon"),
        ({"radius_s": 0}, "radius_s"),
    ],
)
def test_invalid_parameters_raise_value_error_naming_them(change, fragment):
    with pytest.raises(ValueError, match=fragment):
        CDNFParams(**change)

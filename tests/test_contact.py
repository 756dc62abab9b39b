"""Hertz contact: constants, force law and the linearised stiffness vs a numerical derivative."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpaper import contact


def test_hertz_constants_from_formula():
    R = 0.42
    assert contact.hertz_constant(R, "worn") == pytest.approx(3.86 * R ** -0.115 * 1e-8, rel=1e-15)
    assert contact.hertz_constant(R, "conical") == pytest.approx(4.57 * R ** -0.149 * 1e-8, rel=1e-15)
    # hand value for R = 0.42 m: 3.86e-8 * 0.42^-0.115 = 4.265e-8 m/N^(2/3)
    assert contact.hertz_constant(R) == pytest.approx(4.2649e-8, rel=1e-4)


@settings(max_examples=30, deadline=None)
@given(load=st.floats(1e3, 3e5), radius=st.floats(0.3, 0.6))
def test_linearised_stiffness_is_derivative_of_force(load, radius):
    G = contact.hertz_constant(radius)
    delta0 = contact.static_compression(load, G)
    assert contact.hertz_force(delta0, G) == pytest.approx(load, rel=1e-12)
    h = delta0 * 1e-6
    numerical = (contact.hertz_force(delta0 + h, G) - contact.hertz_force(delta0 - h, G)) / (2 * h)
    assert contact.linearised_stiffness(load, G) == pytest.approx(float(numerical), rel=1e-8)


def test_force_zero_when_contact_lost():
    G = contact.hertz_constant(0.42)
    np.testing.assert_array_equal(contact.hertz_force([-1e-5, 0.0], G), [0.0, 0.0])
    assert contact.hertz_force(1e-4, G) > 0


def test_bad_input():
    with pytest.raises(ValueError, match="unknown tread"):
        contact.hertz_constant(0.42, "flat")
    with pytest.raises(ValueError, match="must be > 0"):
        contact.linearised_stiffness(-1.0, 4e-8)

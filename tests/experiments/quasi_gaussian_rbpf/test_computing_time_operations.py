"""The operation count that decides the computing-time claims (computing_time.operations_per_step)."""

import pytest

from railpaper.engine import bank_multiply_adds
from railpaper.experiments.quasi_gaussian_rbpf.computing_time import (
    PAIRED,
    operation_metrics,
    operations_per_step,
)


@pytest.mark.parametrize("name", PAIRED)
def test_shared_parts_and_linear_growth(name):
    """Every filter's count holds one Kalman step per particle; doubling N doubles every part
    but the search's N log2 N comparisons and the Cholesky factor (independent of N)."""
    n, p, d = 2, 2, 2
    small, large = (operations_per_step(name, N, n, p, d) for N in (512, 1024))
    assert small["kalman bank"] == 512 * bank_multiply_adds(n, p, 0)
    for part in small:
        if part.startswith("search"):          # N (2 + d + n + n^2) + N log2 N
            copies = 2 + d + n + n * n
            assert small[part] == 512 * (copies + 9) and large[part] == 1024 * (copies + 10)
        elif part in ("Gaussian draws (Eq. 9)", "Liu-West move", "resampling (systematic)"):
            assert large[part] - 2 * small[part] == -(d ** 3 // 6 if "system" not in part else 1)
        else:
            assert large[part] == 2 * small[part], part


def test_ratios_and_the_printed_reading():
    m = operation_metrics(1000, n=2, p=2, d=2)
    for q in PAIRED[1:]:
        assert m[f"operation_ratio_{q}_over_rbpf"] == pytest.approx(
            m[f"operations_per_step_{q}"] / m["operations_per_step_rbpf"])
    # the printed reading evaluates the density of each draw on top: N (d(d+1)/2 + 2d) more
    assert m["operations_per_step_qgrbpf_printed"] - m["operations_per_step_qgrbpf"] == 1000 * 7
    with pytest.raises(ValueError, match="no operation count"):
        operations_per_step("ekf", 10, 2, 2, 2)

"""The readings study of paper 004's noise settings: settling read against a figure's horizon."""

import numpy as np
import pytest

from railpaper.engine import grid_posterior
from railpaper.experiments.quasi_gaussian_rbpf import readings
from railpaper.experiments.quasi_gaussian_rbpf import tables
from railpaper.models.linear_toys import paper004_system
from railpaper.settling import settling_step


def brute_settling(x, tol):
    """Smallest 1-based k with |x[j] - x[-1]| <= tol for every j >= k - 1 (plain loops)."""
    for k in range(1, len(x) + 1):
        if all(abs(x[j] - x[-1]) <= tol for j in range(k - 1, len(x))):
            return k
    raise AssertionError("unreachable: the last sample is within its own band")


@pytest.mark.parametrize("seed", range(20))
def test_settling_to_the_final_value_matches_brute_force(seed):
    x = np.cumsum(np.random.default_rng(seed).normal(size=40)) * 0.1
    for tol in (0.0, 0.05, 0.3, 10.0):
        assert settling_step(np.abs(x - x[-1]) <= tol) == brute_settling(list(x), tol)


def test_readings_file_has_units_and_sources():
    rows, horizons = readings.load_readings()
    assert {r.key for r in rows} >= {"printed", "qr_std"}
    assert all(r.q_var > 0 and r.r_var > 0 and r.p0_std > 0 and r.source for r in rows)
    assert horizons == tuple(sorted(horizons)) and min(horizons) >= 55


def test_study_reads_each_horizon_against_its_own_last_value(tmp_path):
    path = tmp_path / "readings.toml"
    path.write_text('[one]\nlabel = "x"\nq_var = 0.001\nr_var = 0.001\np0_std = 0.05\n'
                    'source = "test"\n[horizons]\nvalues = [12, 60]\n')
    study = readings.run_readings(n_records=3, grid_size=15, path=path)
    lower, upper = np.array([-1.0, 1.0]), np.array([0.4, 2.8])
    reading = readings.load_readings(path)[0][0]
    for r in range(3):
        mean, _ = readings.posterior_paths(reading, (-0.7, 1.5), lower, upper, 60, 15, 0, r)
        for h, H in enumerate((12, 60)):
            # a posterior after H steps does not depend on later data: the same grid run on
            # the first H measurements only gives the same path
            for j in range(2):
                assert study.settling_steps[0, h, j, r] == brute_settling(list(mean[:H, j]), 0.05)
    # the whole-record path equals a fresh posterior on the record truncated to H steps
    rng = np.random.default_rng(np.random.SeedSequence([0, readings.STREAM, 0]))
    from railpaper.models.linear_toys import simulate_paper004
    sim = simulate_paper004(-0.7, 1.5, 0.001, 0.001, 0.05, 60, rng)
    short = grid_posterior(paper004_system(0.001, 0.001), sim.y[:12], lower, upper, 15,
                           np.zeros(2), 0.05 ** 2 * np.eye(2))
    full, _ = readings.posterior_paths(reading, (-0.7, 1.5), lower, upper, 60, 15, 0, 0)
    np.testing.assert_allclose(short.mean, full[:12], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="step 55"):
        path.write_text(path.read_text().replace("[12, 60]", "[12, 30]"))
        readings.load_readings(path)
    assert len(study.table) == 2 * 2 and set(study.table.n_records) == {3}
    m = study.metrics()
    assert m["reading_one_settling_step_a_h12_n"] == 3
    assert m["reading_one_settling_step_a_h12_low"] <= m["reading_one_settling_step_a_h12"] \
        <= m["reading_one_settling_step_a_h12_high"]


def test_readings_table_is_a_well_formed_markdown_table(tmp_path):
    """Every row has as many cells as the header (a '|' inside a cell would break the table)."""
    path = tmp_path / "readings.toml"
    path.write_text('[one]\nlabel = "x"\nq_var = 0.001\nr_var = 0.001\np0_std = 0.05\n'
                    'source = "test"\n[horizons]\nvalues = [12, 60]\n')
    table = tables.readings_table(readings.run_readings(n_records=3, grid_size=9, path=path))
    rows = table.splitlines()
    assert len(rows) == 3 and set(rows[1]) <= set("|-")
    widths = {row.count("|") for row in rows}
    assert widths == {len(rows[0].split("|"))- 1}

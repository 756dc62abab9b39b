"""Evidence of chapter reduced-order-observer (paper 001) against independent references:
the per-column settling index against the shared scalar definition, the batched plant and observer
against the single-run simulators, exact ranks against hand counts and python-control, the
Monte Carlo summaries against scipy's Spearman and numpy medians recomputed from the table."""

import control
import numpy as np
import pandas as pd
import pytest
from scipy import stats as st

from railpaper import track
from railpaper.discretise import foh, simulate_foh
from railpaper.estimators import reduced_order_observer
from railpaper.experiments.reduced_order_observer import evidence as ev
from railpaper.experiments.reduced_order_observer import experiment as chapter
from railpaper.experiments.reduced_order_observer import record
from railpaper.experiments.reduced_order_observer.spec import READINGS, SPEC
from railpaper.models import single_wheelset
from railpaper.settling import settled_index

SMALL = {"speeds_kmh": [60.0, 100.0], "sweep_speeds_kmh": [40.0, 100.0, 160.0], "duration_s": 0.6,
         "error_window_start_s": 0.3, "mc_seeds": 4, "seed": 7}


@pytest.fixture(scope="module")
def small():
    settings = SPEC.resolve(SMALL, quick=True)
    return settings, ev.monte_carlo(settings)


def test_settled_indices_match_scalar_definition():
    rng = np.random.default_rng(3)
    ok = rng.random((50, 200)) < 0.9
    ok[:, 0] = True                      # always holds -> 0
    ok[-1, 1] = False                    # fails at the end -> -1
    ok[:, 2] = False
    ok[-1, 2] = True                     # holds only at the last sample
    expected = [settled_index(ok[:, j]) for j in range(ok.shape[1])]
    assert settled_index(ok).tolist() == expected
    assert expected[:3] == [0, -1, 49]


def test_exact_rank_hand_counts():
    assert ev.exact_rank([[1, 2], [2, 4]]) == 1
    assert ev.exact_rank([[0, 0], [0, 0]]) == 0
    assert ev.exact_rank(np.eye(3)) == 3
    # nearly singular in floats but exactly full rank, and exactly singular despite huge entries
    assert ev.exact_rank([[1.0, 1.0], [1.0, 1.0 + 2.0**-52]]) == 2
    assert ev.exact_rank([[1e20, 3e20], [2e20, 6e20]]) == 1


def test_exact_ctrb_equals_control_on_integers():
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-6.0, -11.0, -6.0]])
    B = np.array([[0.0], [0.0], [1.0]])
    exact = np.array(ev.exact_ctrb(A, B), dtype=float)
    np.testing.assert_array_equal(exact, control.ctrb(A, B))
    assert ev.exact_rank(ev.exact_ctrb(A, B)) == 3
    C = np.array([[1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(np.array(ev.exact_ctrb(A.T, C.T), float).T, control.obsv(A, C))
    assert ev.exact_rank(ev.exact_ctrb(np.diag([1.0, 1.0]), np.array([[1.0], [1.0]]))) == 1


def test_structure_metrics():
    m = ev.structure_metrics(SPEC.resolve({}))
    for r in ev.READINGS:
        assert m[f"rank_Q0_exact_{r}"] == m[f"rank_Q1_exact_{r}"] == 4
        assert m[f"rank_reduced_exact_{r}"] == 2
        assert m[f"rank_Q0_pbh_{r}"] == 4
    assert m["rank_Q0_Q1_exact_min"] == 4 and m["rank_reduced_exact_min"] == 2
    assert m["pole_placement_relative_error_max"] < 1e-9


def test_pole_error_sees_a_wrong_placement(monkeypatch):
    A, B = single_wheelset.state_space(single_wheelset.load_parameters())
    assert ev._pole_error(A, B, [-30.0, -40.0]) < 1e-9
    real_design = reduced_order_observer.design
    monkeypatch.setattr(reduced_order_observer, "design",
                        lambda A, B, n1, poles: real_design(A, B, n1, [-30.0, -41.0]))
    assert ev._pole_error(A, B, [-30.0, -40.0]) == pytest.approx(1 / 40, rel=1e-6)


@pytest.mark.parametrize("reading", ev.READINGS)
def test_batched_plant_and_observer_equal_single_runs(reading):
    vehicle = single_wheelset.load_parameters(p0_basis=reading)
    A, B = single_wheelset.state_space(vehicle)
    dt, t = 1e-4, np.arange(0, 0.2, 1e-4)
    q = np.column_stack([1e-3 * np.sin(2 * np.pi * f * t) + c for f, c in ((3, 0), (17, 2e-4))])
    y, z_w = record._plant_batch(vehicle, "linear", dt, q)
    obs = reduced_order_observer.design(A, B, 2, [-30.0, -40.0]).discretise(dt, "zoh")
    x2_initial = np.column_stack([np.zeros(2), q[0] + 5e-3])
    z_est = record._observer_batch(obs, y, q, x2_initial)
    for j in range(2):
        x = simulate_foh(*foh(A, B, dt), q[:, j:j + 1], [0.0, q[0, j], 0.0, q[0, j]])
        np.testing.assert_allclose(y[:, j], x[:, :2], rtol=1e-10, atol=1e-16)
        np.testing.assert_allclose(z_w[:, j], x[:, 3], rtol=1e-10, atol=1e-16)
        single = obs.run(x[:, :2], q[:, j:j + 1], x2_initial[j])[:, 1]
        np.testing.assert_allclose(z_est[:, j], single, rtol=1e-9, atol=1e-15)
    yh, zh = record._plant_batch(vehicle, "hertz", dt, q[:300])
    xh = record._simulate_hertz(vehicle, t[:300], q[:300, 1], [0.0, q[0, 1], 0.0, q[0, 1]])
    np.testing.assert_allclose(zh[:, 1], xh[:, 3], rtol=1e-10, atol=1e-16)


def test_monte_carlo_sample_equals_single_run(small):
    settings, table = small
    assert len(table) == settings.mc_seeds * 4 * len(ev.READINGS)       # 4 distinct speeds
    for seed in (settings.seed, settings.seed + 2):
        for reading in ev.READINGS:
            single = chapter.run(settings.replace(seed=seed, p0_basis=reading,
                                                  side_tables=False)).metrics
            rows = table[(table.seed == seed) & (table.reading == reading)].set_index("speed_kmh")
            for speed in settings.speeds_kmh:
                lab, row = f"{speed:g}kmh", rows.loc[speed]
                assert row.convergence_time_s == single[f"convergence_time_s_{lab}"]
                assert row.force_rms_error_N == pytest.approx(single[f"force_rms_error_N_{lab}"],
                                                              rel=1e-9)
                assert row.displacement_rms_error_m == pytest.approx(
                    single[f"displacement_rms_error_m_{lab}"], rel=1e-9)


def test_fixed_noise_equals_proportional_at_reference_speed(small):
    settings, table = small
    ref = table[table.speed_kmh == settings.speeds_kmh[0]]
    np.testing.assert_allclose(ref.force_rms_error_N_fixed_noise, ref.force_rms_error_N, rtol=1e-12)
    other = table[table.speed_kmh == 160.0]
    assert not np.allclose(other.force_rms_error_N_fixed_noise, other.force_rms_error_N, rtol=1e-3)


def test_noise_as_printed_is_the_run_without_sensor_noise():
    # D as printed puts the noise on Z_w alone, which the observer never reads: its columns are
    # the default columns of a run with no sensor noise on the channels it reads, bit for bit,
    # and they differ from the noisy ones
    settings = SPEC.resolve(SMALL, quick=True)
    seeds = (settings.seed, settings.seed + 1)
    rows = ev.monte_carlo_rows(settings, seeds)
    quiet = ev.monte_carlo_rows(settings.replace(noise_fraction=0.0, track_noise_fraction=0.0),
                                seeds)
    for name in ("convergence_time_s", "displacement_rms_error_m",
                 "displacement_relative_rms_error", "force_rms_error_N",
                 "force_relative_rms_error"):
        for reading in READINGS:
            for speed in ev.all_speeds(settings):
                printed = ev.sample_column(name + ev.NOISE_AS_PRINTED, reading, speed)
                default = ev.sample_column(name, reading, speed)
                np.testing.assert_array_equal(rows[printed], quiet[default])
    noisy = ev.sample_column("displacement_rms_error_m", "wheel", 60.0)
    assert not np.allclose(rows[noisy], quiet[noisy], rtol=1e-3)


def test_evidence_metrics_recomputed_by_hand(small):
    settings, table = small
    m = ev.evidence_metrics(table, settings)
    speeds = [40.0, 60.0, 100.0, 160.0]
    for r in ev.READINGS:
        t = table[table.reading == r]
        wide = {c: t.pivot(index="seed", columns="speed_kmh", values=c) for c in
                ("convergence_time_s", "force_rms_error_N_fixed_noise", "force_relative_rms_error")}
        conv = wide["convergence_time_s"].where(wide["convergence_time_s"] >= 0,
                                                settings.duration_s)
        worst = conv[list(settings.speeds_kmh)].max(axis=1).to_numpy()
        assert m[f"mc_convergence_time_s_worst_{r}"] == pytest.approx(np.median(worst))
        assert m[f"mc_convergence_time_s_worst_{r}_n"] == settings.mc_seeds
        assert m[f"mc_convergence_time_s_worst_{r}_low"] == worst.min()   # n = 4: [min, max]
        worst_f = wide["force_relative_rms_error"][list(settings.speeds_kmh)].max(axis=1)
        assert m[f"mc_force_relative_rms_error_worst_{r}"] == pytest.approx(np.median(worst_f))
        values = wide["force_rms_error_N_fixed_noise"][speeds].to_numpy()
        rhos = [st.spearmanr(speeds, row).statistic for row in values]
        name = f"mc_trend_force_rms_error_fixed_noise_rho_{r}"
        assert m[name] == pytest.approx(np.median(rhos))
        assert m[f"{name}_rising_fraction"] == pytest.approx(np.mean(np.array(rhos) > 0))
        ratio = values[:, -1] / values[:, 0]
        assert m[f"mc_ratio_force_rms_error_fixed_noise_{r}"] == pytest.approx(np.median(ratio))
        assert m[f"mc_convergence_never_{r}"] == int((t.convergence_time_s < 0).sum())


def test_never_converged_counts_as_duration():
    settings = SPEC.resolve(dict(SMALL, sweep_speeds_kmh=[100.0]), quick=True)
    rows = []
    for seed in range(3):
        for speed, conv in ((60.0, 0.1), (100.0, -1.0 if seed == 0 else 0.2)):
            for r in ev.READINGS:
                rows.append({"seed": seed, "speed_kmh": speed, "reading": r,
                             **{c: 1.0 + speed for c in ev.SAMPLE_COLUMNS},
                             "convergence_time_s": conv})
    table = pd.DataFrame(rows)
    m = ev.evidence_metrics(table, settings)
    assert m["mc_convergence_time_s_worst_wheel"] == 0.2          # median of [0.6, 0.2, 0.2]
    assert m["mc_convergence_time_s_worst_wheel_high"] == settings.duration_s
    assert m["mc_convergence_never_wheel"] == 1


def test_hertz_linearisation_error_scales_with_the_irregularity_amplitude(small):
    """The linearised contact's error is second order in the dynamic deflection: relative to the
    force it falls in proportion to the irregularity's amplitude (the Taylor remainder of
    (δ0 + δ)^(3/2) about δ0), so halving q halves it; no observer is involved, so the observer's
    initial error changes nothing; the Monte Carlo table holds the same number for its sample,
    under both readings of P0."""
    settings, table = small
    distance_m, profile_m = record.profile(settings, settings.seed)
    t_s, q = track.wheelset_inputs(distance_m, profile_m, settings.speeds_kmh[0] / 3.6, [0.0],
                                   settings.dt_s, settings.duration_s)
    law = "force_relative_rms_error_hertz"
    full, half = (ev._hertz_samples(settings.p0_basis, settings, t_s, scale * q, [0])[law][0]
                  for scale in (1.0, 0.5))
    assert 0 < half < full
    assert full / half == pytest.approx(2.0, rel=0.15)
    assert ev._hertz_samples(settings.p0_basis, settings.replace(initial_error_m=0.0), t_s, q,
                             [0])[law][0] == full
    for reading in READINGS:
        row = table[(table.seed == settings.seed) & (table.reading == reading)
                    & (table.speed_kmh == settings.speeds_kmh[0])]
        one = ev._hertz_samples(reading, settings, t_s, q, [0])
        for column in one:                                      # one column vs a batch
            assert row[column].iloc[0] == pytest.approx(one[column][0], rel=1e-9)
    sweep_only = table[~table.speed_kmh.isin(settings.speeds_kmh)]
    assert sweep_only.force_relative_rms_error_hertz.isna().all()

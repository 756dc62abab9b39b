"""Chapter rbpf-parameter-estimation: quick run within tolerances, validation, robustness."""

import math

import numpy as np
import pandas as pd
import pytest
from conftest import railpaper_cli

from railpaper.data import read_toml
from railpaper.engine import run_rbpf
from railpaper.experiments.base import ParameterError, check_metrics
from railpaper.experiments.lateral_vehicle import RecordSettings, prior_centre
from railpaper.experiments.rbpf_parameter_estimation import experiment as chapter
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.experiments.rbpf_parameter_estimation import measurements
from railpaper.models import lateral_16state
from railpaper.paths import DATA_DIR
from railpaper.pipeline.claim_rules import is_untestable, rule_metrics
from railpaper.settling import settling_step

PARAMS = ("csy", "lambda", "kpy", "ksy", "csaly")
REQUIRED = (["steps_to_within_5pct_all", "steps_to_within_5pct_all_paper_scheme",
             "ekf_lateral_converged_of_10", "toy_ekf_diverged_init1", "toy_ekf_diverged_init2",
             "toy_final_abs_error_max_rbpf_init1"]
            + [f"{k}_{p}{s}" for p in PARAMS for s in ("", "_paper_scheme")
               for k in ("steps_to_within_5pct", "final_relative_error")]
            + [f"crlb_rel_350_{p}" for p in PARAMS])


@pytest.fixture(scope="module")
def quick_result():
    """run() in this process at quick sizes with fewer records (the quick book's papermill run
    at the full quick sizes is what the tolerance test reads); paper_records > n_records, so
    records filtered by the paper scheme alone, and by the working scheme alone, are in it."""
    settings = chapter.SPEC.resolve({"toy_seeds": 6, "n_records": 3, "ibis_records": 2,
                                     "mismatch_records": 2, "working_records": 4}, quick=True)
    assert settings.paper_records > settings.working_records > settings.n_records
    return settings, chapter.run(settings)


def test_quick_book_run_is_within_tolerances(quick_chapter_dir):
    from railpaper.pipeline.check import check_chapter

    chapter_dir = quick_chapter_dir("rbpf-parameter-estimation")
    rows = check_chapter("rbpf-parameter-estimation", chapter_dir)
    assert rows and all(r.status == "ok" for r in rows), [
        (r.metric, r.value, r.band) for r in rows if r.status != "ok"]


def test_quick_run_has_every_key(quick_result):
    settings, result = quick_result
    metrics = check_metrics(result.metrics)
    for key in REQUIRED:
        assert key in metrics, key
    claims = read_toml(DATA_DIR / "rbpf-parameter-estimation" / "claims.toml")
    for key, row in claims.items():                 # run() alone gives every metric a rule reads
        for name in ([] if is_untestable(row) else rule_metrics(row)):
            assert name in metrics, (key, name)
    from railpaper.experiments.rbpf_parameter_estimation import STUDIES
    from railpaper.pipeline.declarations import load_declarations
    computes = {s.name: s.repeats or s.name for s in STUDIES}  # a repeat: only stored evidence
    for d in load_declarations("rbpf-parameter-estimation"):   # every declared column exists
        if d.study:
            table = result.extra_tables[f"records_{computes[d.study]}"]
            assert all(name in table.columns for name in d.metrics), (d.id, d.metrics)
        else:
            assert all(name in metrics or name in result.timings for name in d.metrics), d.id
    assert isinstance(metrics["toy_ekf_diverged_init1"], bool)
    assert metrics["lateral_within_5pct_from_350_rate_paper_scheme_n"] == settings.paper_records
    ts = result.timeseries
    assert list(ts.columns[:6]) == ["t_s"] + [f"{p}_norm" for p in PARAMS]
    assert len(ts) == settings.n_steps and math.isclose(ts.t_s.iloc[0], settings.dt_s)
    toy = result.extra_tables["toy_timeseries"]
    assert toy.columns[0] == "step" and len(toy) == settings.toy_steps


def test_toy_only_sample_is_one_record_of_the_main_run(quick_result):
    """A toy sample (toy_seeds=1, lateral=False, seed s) is record s of the main run."""
    settings, result = quick_result
    seed = settings.seed + 3
    sample = chapter.run(settings.replace(seed=seed, toy_seeds=1, lateral=False))
    assert sample.timeseries is None
    assert not any(k.startswith(("critical_speed", "steps_to_within", "crlb", "ekf_lateral",
                                 "lateral_")) for k in sample.metrics)
    stats = result.toy.records
    for ic in (1, 2):
        row = stats[(stats.seed == seed) & (stats.init == ic)].iloc[0]
        assert sample.metrics[f"toy_final_abs_error_max_rbpf_init{ic}"] == row.rbpf_err_max
        assert sample.metrics[f"toy_ekf_final_abs_error_max_init{ic}"] == row.ekf_err_max
        assert sample.metrics[f"toy_final_abs_error_max_rbpf_working_init{ic}"] == \
            row.rbpf_working_err_max
    assert sample.metrics["toy_ekf_converge_rate_init2"] == float(
        stats[(stats.seed == seed) & (stats.init == 2)].ekf_converged.iloc[0])


def test_monte_carlo_records_are_consecutive_seeds(quick_result):
    """Records seed, seed + 1, ... (so seed batches k * 1000 are disjoint), each filtered from
    both initial conditions; the lateral evidence counts n_records records."""
    settings, result = quick_result
    stats = result.toy.records
    seeds = list(range(settings.seed, settings.seed + settings.toy_seeds))
    assert sorted(stats[stats.init == 1].seed) == seeds == sorted(stats[stats.init == 2].seed)
    assert [run.seed for run in result.lateral.runs] == list(
        range(settings.seed, settings.seed + settings.n_records))
    assert len(result.lateral.runs) == settings.n_records
    assert result.lateral.paper_scheme_rows.seed.tolist() == list(
        range(settings.seed, settings.seed + settings.paper_records))
    assert result.lateral.working_scheme_rows.seed.tolist() == list(
        range(settings.seed, settings.seed + settings.working_records))
    assert result.metrics["lateral_ekf_converge_rate_n"] == settings.n_records
    assert (result.metrics["rb_augmented_state_dim"], result.metrics["rb_particle_dim"]) == (21, 5)
    for name in ("toy_seeds", "n_records", "paper_records", "working_records"):
        with pytest.raises(ParameterError, match="< 1000"):
            chapter.run(chapter.SPEC.resolve({name: 1000}, quick=True))


def test_notebook_refuses_toy_only_run(tmp_path):
    """lateral = false is for sweep samples: the notebook stops in its first cell, one line."""
    result = railpaper_cli("run", "rbpf-parameter-estimation", "--quick", "-p", "lateral", "false",
                           "--out", str(tmp_path / "out"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "lateral = false is for Monte Carlo samples" in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_steps_to_within():
    norm = np.array([[1.2, 1.0], [1.01, 1.1], [0.99, 1.0], [1.0, 1.2]])
    np.testing.assert_array_equal(settling_step(np.abs(norm - 1.0) <= 0.05), [2, -1])


def test_non_physical_parameters_raise_one_line():
    settings = chapter.SPEC.resolve({"prior_low": 1.1}, quick=True)
    with pytest.raises(ParameterError, match="prior_low"):
        chapter.run(settings)
    settings = chapter.SPEC.resolve({"spectrum": "nope"}, quick=True)
    with pytest.raises(ParameterError, match="spectrum"):
        chapter.run(settings)


def test_measurements_csv_validation(tmp_path):
    settings = chapter.SPEC.resolve({}, quick=True)
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"t_s": np.arange(20) * 1e-3, "acc_w1_mps2": 0.0}).to_csv(bad, index=False)
    with pytest.raises(ParameterError, match="missing column"):
        measurements.read_measurements(str(bad), settings.dt_s)
    good = pd.DataFrame({"t_s": np.arange(20) * 2e-3, **{c: 0.1 for c in lateral_16state.CHANNELS}})
    good.to_csv(tmp_path / "step.csv", index=False)
    with pytest.raises(ParameterError, match="dt_s"):
        measurements.read_measurements(str(tmp_path / "step.csv"), settings.dt_s)
    good["t_s"] = np.arange(20) * 1e-3
    good.to_csv(tmp_path / "ok.csv", index=False)
    rec = measurements.read_measurements(str(tmp_path / "ok.csv"), settings.dt_s)
    assert rec.y.shape == (20, 5) and rec.u_mps is None and rec.seed is None


def test_lateral_rbpf_survives_degenerate_weights():
    fixed, theta = study.vehicle()
    system = lateral_16state.lateral_system(fixed, 300 / 3.6, 1e-3, 1e-12 * np.eye(16),
                                            1e-6 * np.eye(5))
    rng = np.random.default_rng(0)
    y = np.full((30, 5), 1e6)                     # impossible data: every weight underflows
    run = run_rbpf(system, y, theta * rng.uniform(0.5, 1.7, (20, 5)), np.zeros(16),
                   1e-10 * np.eye(16), rng, u=np.zeros((30, 2)), scheme="paper")
    assert np.all(np.isfinite(run.theta_mean)) and np.all(np.isfinite(run.x_mean))


def _steps_by_loop(column, tol=0.05):
    """First step (1-based) from which |x − 1| <= tol to the end, -1 if never: a written-out loop."""
    for k in range(len(column)):
        if all(abs(x - 1.0) <= tol for x in column[k:]):
            return k + 1
    return -1


def test_typed_lateral_result_matches_outputs_and_definitions(quick_result):
    """The named fields are what the pipeline writes and what the metrics were computed from:
    the time series, the per-parameter steps (against a written-out loop), the EKF count and
    guesses per record, and the illustrated record filtered by hand with the estimator."""
    from railpaper.threads import one_thread

    settings, result = quick_result
    lat, m = result.lateral, result.metrics
    assert lat.stack("rbpf_paper_norm").shape == (settings.n_records, settings.n_steps, 5)
    np.testing.assert_array_equal(result.timeseries.t_s, lat.t_s)
    for field, suffix in (("rbpf_working_norm", ""), ("rbpf_paper_norm", "_paper_scheme")):
        norm = getattr(lat.illustrated, field)
        cols = [f"{p}_norm{suffix}" for p in PARAMS]
        np.testing.assert_array_equal(result.timeseries[cols].to_numpy(), norm)
        for j, name in enumerate(PARAMS):
            assert m[f"steps_to_within_5pct_{name}{suffix}"] == _steps_by_loop(norm[:, j])
            assert m[f"final_relative_error_{name}{suffix}"] == norm[-1, j] - 1
    ekf = lat.illustrated.ekf_norm
    assert len(ekf) == settings.ekf_guesses and all(len(r.ekf_norm) == 1 for r in lat.runs[1:])
    within = [bool(np.all(np.abs(r[-1] - 1) <= 0.05)) for r in ekf]
    assert lat.ekf_converged_count == sum(within) == m["ekf_lateral_converged_count"]
    assert list(lat.crlb.parameter) == list(PARAMS)
    np.testing.assert_array_equal(lat.crlb.known_350, [m[f"crlb_rel_350_{p}"] for p in PARAMS])
    fixed, theta = study.vehicle()
    np.testing.assert_array_equal(lat.theta_true, theta)
    with one_thread():                                  # the run's thread settings
        record = study.simulate_lateral(RecordSettings.of(settings), fixed, theta, settings.seed)
        Q, R = study.filter_noise(fixed, theta, RecordSettings.of(settings),
                                  record.du_var_m2ps2)
        rng = np.random.default_rng([settings.seed, 11])   # documented: prior, then the filter
        theta0 = theta * rng.uniform(settings.prior_low, settings.prior_high, (200, 5))
        system = lateral_16state.lateral_system(fixed, settings.speed_kmh / 3.6, settings.dt_s,
                                                Q, R)
        run = run_rbpf(system, record.y, theta0, np.zeros(16), 1e-10 * np.eye(16), rng,
                       u=record.u_mps, scheme="paper", delta=settings.paper_delta)
    np.testing.assert_array_equal(run.theta_mean / theta, lat.illustrated.rbpf_paper_norm)


def test_user_record_input_is_held_one_step(tmp_path):
    """u_k is the track velocity of row k − 1 (row 0 repeated); the process noise is the
    variance of its changes (numpy by hand)."""
    settings = chapter.SPEC.resolve({}, quick=True)
    t = np.arange(30) * 1e-3
    u1, u2 = np.sin(40 * t), np.cos(25 * t)
    frame = pd.DataFrame({"t_s": t, **{c: 0.1 for c in lateral_16state.CHANNELS}, "ydot_t1_mps": u1,
                          "ydot_t2_mps": u2})
    frame.to_csv(tmp_path / "u.csv", index=False)
    rec = measurements.read_measurements(str(tmp_path / "u.csv"), settings.dt_s)
    np.testing.assert_array_equal(rec.u_mps[1:], np.column_stack([u1, u2])[:-1])
    np.testing.assert_array_equal(rec.u_mps[0], [u1[0], u2[0]])
    np.testing.assert_allclose(rec.du_var_m2ps2, [np.var(np.diff(u1)), np.var(np.diff(u2))],
                               rtol=1e-12)


def test_page_structure(quick_result):
    """Issue 14's page from the notebook source: title = SPEC.title, claims glued once at the
    top, rules in the claims section at the end, every figure numbered and referenced, every
    glued name glued, plumbing hidden, short visible cells, no developer words."""
    import json
    import re

    from railpaper.experiments.rbpf_parameter_estimation.tables import caption_values
    from railpaper.paths import BOOK_DIR

    cells = json.loads((BOOK_DIR / "notebooks" / chapter.SPEC.notebook).read_text())["cells"]
    src = ["".join(c["source"]) for c in cells]
    tags = [set(c.get("metadata", {}).get("tags", [])) for c in cells]
    text = "".join(s for s, c in zip(src, cells) if c["cell_type"] == "markdown")
    assert src[0].splitlines()[0] == f"# {chapter.SPEC.title}"
    assert text.count("{glue:md} claims_table") == 1 == "".join(src[:6]).count("claims_table")
    label = next(i for i, s in enumerate(src) if "(claims-rbpf-parameter-estimation)=" in s)
    assert label > len(cells) // 2 and "chapter_rules(CHAPTER)" in src[label + 1]
    for word in ("paper 003", "claims.toml", "railpaper.pipeline", "shared/papers", "data/",
                 "…", "errata.csv", "parameters.toml"):
        assert word not in text, word
    names = re.findall(r"```\{figure\} (\w+)\.png\n:name: (fig-rbpf-[\w-]+)", text)
    assert len(names) == 9 and len({n for _, n in names}) == 9
    for png, name in names:
        assert f"{{numref}}`{name}`" in text
        assert f'save_figure(fig, out_dir, "{png}")' in "".join(src)
    assert not re.search(r"(figure|plot)s? (above|below)", text)
    glued = set(re.findall(r"\{glue:md\}`(\w+)`", text))     # every inline name is glued
    assert len(glued) > 15 and glued <= set(caption_values(quick_result[1], quick_result[0]))
    hidden = {"remove-cell", "remove-input", "hide-input", "parameters"}
    visible = [s for s, t, c in zip(src, tags, cells)
               if c["cell_type"] == "code" and not t & hidden]
    assert len(visible) >= 7
    for s, t, c in zip(src, tags, cells):
        if c["cell_type"] != "code" or "parameters" in t:
            continue
        assert "result.data" not in s and len(s.splitlines()) <= 25, s
        if re.search(r"save_figure\(", s):               # the code of a figure: one click away
            assert {"hide-input", "remove-output"} <= t, s
        elif re.search(r"write_outputs\(|glue\(", s):    # plumbing: hidden
            assert {"remove-input", "remove-cell"} & t, s
    for s in visible:
        assert max(map(len, s.splitlines())) <= 72, s
        for name in ("overrides", "out_dir", "quick"):
            assert not re.search(rf"\b{name}\b", s), (name, s)


def test_exact_posterior_of_the_illustrated_record_is_ibis_as_documented(quick_result):
    """The run's lateral posterior is IBIS called directly with the documented arguments (box
    prior_low..prior_high x theta, x0 = 0, P0 = 1e-10 I, generator [seed, 17]); its sd sits on
    the Cramer-Rao bound (Fisher information of the Kalman likelihood, an independent
    computation: Bernstein-von Mises, flat prior) within the sampler's error, and the RBPF's
    stored spreads are run_rbpf's theta_std."""
    from railpaper.engine import run_ibis
    from railpaper.threads import one_thread

    settings, result = quick_result
    lat = result.lateral
    fixed, theta = study.vehicle()
    with one_thread():
        record = study.simulate_lateral(RecordSettings.of(settings), fixed, theta, settings.seed)
        system = study.filter_system(RecordSettings.of(settings), fixed, theta, record,
                                     theta_ref=prior_centre(theta, settings.prior_low,
                                                            settings.prior_high))
        run = run_ibis(system, record.y, settings.prior_low * theta,
                       settings.prior_high * theta, np.zeros(16), 1e-10 * np.eye(16),
                       np.random.default_rng([settings.seed, 17]), u=record.u_mps,
                       n_particles=settings.ibis_particles, proposal="independent", min_moves=1)
        paper = study.lateral_rbpf(settings, system, record, theta, settings.seed, "paper")
    post = lat.illustrated.posterior
    np.testing.assert_array_equal(post.mean, run.mean / theta)
    np.testing.assert_array_equal(post.q95, run.q95 / theta)
    np.testing.assert_array_equal(lat.illustrated.rbpf_paper_sd_norm, paper.theta_std / theta)
    crlb = lat.crlb.set_index("parameter")
    for k, col in ((350, "known_350"), (settings.n_steps, f"known_{settings.n_steps}")):
        ratio = post.sd[k - 1] / crlb[col].to_numpy()
        assert np.all((ratio > 0.7) & (ratio < 1.4)), (k, ratio)
    assert sum(r.posterior is not None for r in lat.runs) == min(settings.ibis_records,
                                                                 settings.n_records)


def test_lateral_posterior_metrics_count_by_hand(quick_result):
    """Coverage, the posterior's 5 %-from-350 rate and the sd medians, counted by loops over
    the typed result, with scipy's exact binomial interval."""
    from scipy.stats import binomtest

    settings, result = quick_result
    m, runs = result.metrics, [r for r in result.lateral.runs if r.posterior is not None]
    z = 1.6448536269514722
    counts = {"exact_posterior": 0, "paper_scheme": 0, "tempered": 0}
    within = 0
    for r in runs:
        p = r.posterior
        for j in range(5):
            counts["exact_posterior"] += p.q05[-1, j] <= 1.0 <= p.q95[-1, j]
            counts["paper_scheme"] += abs(r.rbpf_paper_norm[-1, j] - 1) <= z * \
                r.rbpf_paper_sd_norm[-1, j]
            counts["tempered"] += abs(r.rbpf_working_norm[-1, j] - 1) <= z * \
                r.rbpf_working_sd_norm[-1, j]
        within += all(abs(p.mean[k, j] - 1) <= 0.05 for k in range(349, len(p.mean))
                      for j in range(5))
    n = 5 * len(runs)
    for name, k in counts.items():
        key = f"coverage_90_{name}_lateral"
        ci = binomtest(int(k), n).proportion_ci(0.95, method="exact")
        assert (m[key], m[key + "_n"]) == (k / n, n)
        assert (m[key + "_low"], m[key + "_high"]) == pytest.approx((ci.low, ci.high), abs=1e-9)
    assert m["lateral_within_5pct_from_350_rate_posterior"] == within / len(runs)
    sd350 = np.array([r.posterior.sd[349] for r in runs])
    assert m["posterior_sd_rel_350_max"] == pytest.approx(np.median(sd350.max(axis=1)))
    for j, name in enumerate(PARAMS):
        assert m[f"posterior_sd_rel_350_{name}"] == runs[0].posterior.sd[349, j]
        assert m[f"posterior_sd_rel_350_median_{name}"] == pytest.approx(np.median(sd350[:, j]))


@pytest.mark.parametrize("scheme", ["paper", "working"])
def test_each_scheme_runs_on_its_records_and_its_metrics_read_all_of_them(quick_result, scheme):
    """Records n_records … <scheme>_records − 1 get that scheme alone: each equals the scheme
    run on its own on a freshly simulated record, and the scheme's rate reads all its records
    (hand count)."""
    from railpaper.settling import holds_from
    from railpaper.threads import one_thread

    settings, result = quick_result
    part, m = result.lateral, result.metrics
    rows = getattr(part, f"{scheme}_scheme_rows")
    n_total = {"paper": settings.paper_records, "working": settings.working_records}[scheme]
    assert n_total > settings.n_records and len(rows) == n_total
    fixed, theta = study.vehicle()
    seed = settings.seed + n_total - 1                                 # the last one
    with one_thread():
        record = study.lateral_record(settings, fixed, theta, seed)
        alone = study.run_lateral_rbpf(settings, fixed, theta, record, seed, scheme)
    last = rows.iloc[-1]
    assert last.seed == seed
    assert bool(last.within_5pct_from_350) == bool(holds_from(np.abs(alone - 1.0) <= 0.05,
                                                              350).all())
    for j, name in enumerate(lateral_16state.PARAM_NAMES):
        assert last[f"final_relative_error_{name}"] == alone[-1, j] - 1.0
    stacked = part.stack(f"rbpf_{scheme}_norm")            # the first n_records, in full
    hand = sum(bool(holds_from(np.abs(r - 1.0) <= 0.05, 350).all()) for r in stacked)
    assert rows.within_5pct_from_350.iloc[:settings.n_records].sum() == hand
    hand += int(rows.within_5pct_from_350.iloc[settings.n_records:].sum())
    assert m[f"lateral_within_5pct_from_350_rate_{scheme}_scheme_n"] == n_total
    assert m[f"lateral_within_5pct_from_350_rate_{scheme}_scheme"] == hand / n_total

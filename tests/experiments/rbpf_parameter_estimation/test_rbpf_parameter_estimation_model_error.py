"""The chapter's model-error metrics: the matched (linear-plant) side taken from Part 2's records
equals run_mismatch's own filtering of those records, and the paired counts equal a hand count."""

import numpy as np

from railpaper.experiments.rbpf_parameter_estimation import experiment as chapter
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.experiments.rbpf_parameter_estimation.mismatch import run_mismatch


def test_matched_metrics_from_part_two_equal_run_mismatch():
    settings = chapter.SPEC.resolve({"toy_seeds": 1, "n_records": 2, "ibis_records": 1,
                                     "mismatch_records": 2, "ekf_guesses": 2,
                                     "paper_records": 2, "working_records": 2,
                                     "toy_ibis_records": 1, "toy_ibis_particles": 50,
                                     "ibis_particles": 50}, quick=True)
    result = chapter.run(settings)
    m = result.metrics
    direct = run_mismatch(settings, 2, matched=True)          # filters the matched plant itself
    for key, value in direct.metrics.items():
        assert key in m, key
        assert m[key] == value or (np.isnan(value) and np.isnan(m[key])), (key, m[key], value)
    rows = direct.records.set_index(["plant", "seed"])
    for r in result.lateral.runs:                           # Part 2's record = the matched one
        np.testing.assert_array_equal(direct.rbpf["matched"][r.seed - settings.seed],
                                      r.rbpf_working_norm)
        assert rows.loc[("matched", r.seed), "ekf_converged"] == study.ekf_converged(
            r.ekf_norm[0])
    lost = sum(rows.loc[("matched", s), "rbpf_all_within"]
               and not rows.loc[("mismatch", s), "rbpf_all_within"] for s in (0, 1))
    assert m["rbpf_within_lost_mismatch"] == lost
    assert result.mismatch.ekf_first["mismatch"][0].shape == (settings.ekf_steps, 5)

"""The Performance page comes wholly from one bench payload; a busy machine prints no ratio.

The timing helpers interleave the compared engines (A B A B …) and summarise medians with their
spread; the benchmark's orchestration is run with fake timings to check the order of the timed
runs and the payload's keys without spending minutes.
"""

import re
from pathlib import Path

import numpy as np
import pytest

from railpaper.bench import rbpf_engine as engine
from railpaper.bench.report import (
    PROFILE_LABELS,
    WITHHELD,
    busy_note,
    findings_markdown,
    format_markdown,
    format_table,
    ratio_verdict,
    setup_markdown,
    write_performance_files,
)
from railpaper.experiments.rbpf_parameter_estimation.spec import SPEC

BOOK = Path(__file__).resolve().parents[2] / "book"

#: The bench JSON's top-level keys before issue 15 (kept) and the ones it added.
OLD_KEYS = {"steps_per_s_rbpf_lateral_N1000", "steps_per_s_rbpf_lateral_N1000_paper_scheme",
            "steps_per_s_rbpf_lateral_N1000_step_api", "steps_per_s_rbpf_lateral_N1000_settled",
            "settled_window", "steps_per_s_qgrbpf_lateral_N1000",
            "speedup_vs_filterpy_lateral_N1000", "speedup_vs_filterpy_lateral_N1000_paper_scheme",
            "speedup_vs_numpy_lateral_N1000", "speedup_vs_numpy_lateral_N1000_paper_scheme",
            "profile_N1000_ms", "memory_N10000", "quick", "sizes", "machine", "rows"}
NEW_KEYS = {"steps_per_s_rbpf_lateral_N1000_first1000", "resamplings_first1000", "spread",
            "repeats", "setup", "gain_settling", "bank_call_N1000_ms"}


def payload(load=(0.5, 0.4, 0.3), load_max=None):
    rows = [dict(problem="lateral-16", filter=f, engine="compiled", N=1000, steps=200,
                 steps_per_s=s, steps_per_s_min=s - 5, steps_per_s_max=s + 7, repeats=5,
                 us_per_particle_step=1e6 / s / 1000)
            for f, s in (("rbpf-working", 237.0), ("rbpf-paper", 100.0), ("qgrbpf", 46.0))]
    rows.append(dict(problem="lateral-16", filter="rbpf-paper", engine="filterpy", N=1000,
                     steps=25, steps_per_s=11.1, steps_per_s_min=10.0, steps_per_s_max=12.0,
                     repeats=5, us_per_particle_step=90.0, speedup_of_compiled=9.37,
                     speedup_of_compiled_min=8.71, speedup_of_compiled_max=9.93,
                     max_rel_theta_diff=3e-15))
    machine = dict(cores=2, cpu="x", python="3.11", numpy="2", blas="openblas", numba="0.6",
                   numba_threads=2, load_before=list(load), load_after=list(load))
    if load_max is not None:
        machine["load_max_1min"] = load_max
    return dict(
        steps_per_s_rbpf_lateral_N1000=237.0, steps_per_s_rbpf_lateral_N1000_paper_scheme=100.0,
        steps_per_s_rbpf_lateral_N1000_step_api=200.0,
        steps_per_s_rbpf_lateral_N1000_settled=690.0, settled_window={"skip": 2000, "steps": 1000},
        steps_per_s_qgrbpf_lateral_N1000=46.0, speedup_vs_filterpy_lateral_N1000=14.1,
        speedup_vs_filterpy_lateral_N1000_paper_scheme=9.37, speedup_vs_numpy_lateral_N1000=2.9,
        speedup_vs_numpy_lateral_N1000_paper_scheme=2.8, time_ratio_qgrbpf_over_rbpf_N1000=2.17,
        steps_per_s_rbpf_lateral_N1000_first1000=241.0, resamplings_first1000=183,
        spread={"time_ratio_qgrbpf_over_rbpf_N1000": [2.01, 2.33],
                "speedup_vs_filterpy_lateral_N1000": [13.2, 15.0]},
        repeats=5, gain_settling=dict(gain_change_after_first=2.1e-5, gain_change_after=3.2e-8,
                                      steps=3000, slowest_observable_abs_eig=0.99712),
        setup=dict(states=16, channels=5, dt_s=0.001, speed_kmh=300.0, ess_fraction=0.8,
                   tempering_steps=300, working_delta=0.9, paper_delta=0.98, max_chunk=32,
                   first_steps=1000, particles=[100, 1000, 10000], baseline_N=1000),
        profile_N1000_ms={"kalman_bank_ms": 1.5, "zoh_all_particles_ms": 6.0,
                          "rest_of_paper_scheme_step_ms": 1.5},
        bank_call_N1000_ms={"one_step_call_ms": 1.7, "per_step_in_long_call_ms": 0.9,
                            "fixed_cost_per_call_ms": 0.8, "steps_of_long_call": 32},
        memory_N10000={"peak_rss_mb": 482.0, "particles_mb": 242.0, "bank_arrays_mb": 60.0},
        machine=machine, quick=True,
        sizes={"working": 1000, "paper": 200, "fp_working": 150, "fp_paper": 25}, rows=rows)


def test_findings_quote_the_payload():
    text = findings_markdown(payload())
    assert "costs 0.80 ms besides its steps (47% of a one-step call, 1.70 ms" in text
    assert "inside a 32-step call takes 0.90 ms" in text
    old = payload()
    del old["bank_call_N1000_ms"]                      # a payload from before the measurement
    assert "A call of the Kalman bank" not in findings_markdown(old)
    assert "237 steps/s (0.24 × real time" in text and "690 steps/s" in text
    assert "Steps 1–1000 at N = 1000" in text and "241 steps/s" in text
    assert "183 resamplings" in text
    assert "14.1× (working scheme) and 9.4× (paper scheme)" in text
    assert "takes 9.0 ms" in text and f"{PROFILE_LABELS['zoh_all_particles_ms']} 6.00 ms (67%)" in text
    assert "2.1e-05" in text and "3.2e-08 after 3000" in text and "0.9971" in text


def test_quiet_run_prints_ratios_with_their_spread():
    assert ratio_verdict(payload()["machine"])[0]
    md = format_markdown(payload())
    assert "| 9.4 (8.7–9.9) |" in md and "N = 1000: 2.17 (2.01–2.33)" in md
    assert "| 237.0 (232.0–244.0) |" in md
    table = format_table(payload())
    assert "9.4 (8.7-9.9)" in table and "time_ratio_qgrbpf_over_rbpf_N1000 = 2.17" in table
    assert WITHHELD not in table + md


@pytest.mark.parametrize("load, load_max", [((5.2, 3, 2), None), ((0.3, 0.3, 0.3), 2.6)])
def test_busy_run_prints_no_ratio_and_says_why(load, load_max):
    p = payload(load, load_max)
    ok, reason = ratio_verdict(p["machine"])
    assert not ok and "ratios withheld" in reason and "on 2 cores" in reason
    texts = [format_markdown(p), findings_markdown(p), format_table(p), busy_note(p["machine"])]
    for text in texts:
        for ratio in ("9.4", "8.7", "9.9", "2.17", "2.01", "2.33", "14.1", "2.9×", "2.8×"):
            assert ratio not in text, (ratio, text)
    assert texts[0].count(f"| {WITHHELD} |") == 1 and "ratios withheld" in texts[0]
    assert "ratios withheld" in texts[1]
    assert "speedup_vs_filterpy_lateral_N1000 = withheld" in texts[2]
    assert texts[3].startswith("**The machine was busy**")
    assert "241 steps/s" in texts[1]                    # rates are still shown


def test_unrecorded_load_withholds_ratios():
    assert not ratio_verdict({"cores": 2})[0]
    assert "not recorded" in busy_note({"cores": 2})


def test_table_has_every_row():
    assert format_markdown(payload()).count("| lateral") == 0
    assert format_markdown(payload()).count("| compiled |") == 3


def test_setup_lists_the_run_settings():
    text = setup_markdown(payload())
    assert "16 states, 5 measurement channels" in text and "1000 steps/s is real time" in text
    assert "ESS < 0.8 N" in text and "first 300 steps" in text and "up to 32 steps" in text
    assert "5 alternations" in text and "N = 100, 1000, 10000" in text


def test_page_has_no_hand_typed_numbers_and_its_includes_are_generated(tmp_path):
    """Every number on the Performance page comes from the generated files: the page's own
    text holds none (paper numbers aside), and every file it includes is written by
    write_performance_files from the payload."""
    page = (BOOK / "performance.md").read_text()
    prose = re.sub(r"```.*?```", "", page, flags=re.S)
    prose = re.sub(r"`[^`]*`", "", prose)
    prose = re.sub(r"\b[Pp]aper 00\d\b", "", prose)
    prose = "\n".join(ln for ln in prose.splitlines() if not ln.startswith(":"))
    assert re.findall(r"\d", prose) == [], prose
    included = set(re.findall(r"_generated/([\w.]+)", page))
    write_performance_files(payload(), tmp_path)
    assert included and included <= {f.name for f in tmp_path.iterdir()}


def test_the_bench_is_a_package_module_not_loaded_by_path():
    from railpaper.bench import report
    assert engine.__name__ == "railpaper.bench.rbpf_engine" and report.engine is engine
    assert engine.__file__.endswith("railpaper/bench/rbpf_engine.py")
    assert engine.FilterpyRBPF.__module__ == "railpaper.bench.filterpy_rbpf"


def test_interleaving_and_summaries():
    from railpaper.timing import LoadLog, interleaved, paired_ratio, summary
    calls = []
    out = interleaved({n: (lambda n=n: calls.append(n) or len(calls)) for n in "ABC"}, 5)
    assert calls == list("ABC") * 5 and out["B"] == [2, 5, 8, 11, 14]
    assert summary([3.0, 1.0, 2.0, 10.0, 4.0]) == dict(median=3.0, min=1.0, max=10.0, n=5)
    r = paired_ratio([2.0, 4.0, 9.0], [1.0, 1.0, 3.0])
    assert (r["median"], r["min"], r["max"]) == (3.0, 2.0, 4.0)
    loads = iter([(0.1, 0, 0), (3.5, 0, 0), (0.2, 0, 0)])
    log = LoadLog(clock=iter(range(10)).__next__, load=lambda: next(loads))
    for label in ("start", "mid", "end"):
        log.sample(label)
    d = log.as_dict()
    assert d["load_before"][0] == 0.1 and d["load_after"][0] == 0.2 and d["load_max_1min"] == 3.5


def test_orchestration_interleaves_and_keeps_the_keys(monkeypatch):
    """main_payload with fake timings: every comparison alternates its engines, >= 5 times,
    and the payload has the old top-level keys and the new ones."""
    calls = []
    settings = SPEC.resolve({}, False)
    monkeypatch.setattr(engine, "lateral_problem", lambda n: dict(settings=settings))

    def fake_time(prob, kind, N, n_steps, per_step=False, skip=0):
        calls.append((kind + (":step" if per_step else ""), N))
        return 1e-3 * (1 + len(kind) / 10), np.ones((n_steps, 5))
    monkeypatch.setattr(engine, "time_filter", fake_time)
    monkeypatch.setattr(engine, "working_timeline", lambda *a, **k: (4e-3, 1e-3, 183))
    monkeypatch.setattr(engine, "profile_step", lambda *a: dict.fromkeys(PROFILE_LABELS, 1.0))
    monkeypatch.setattr(engine, "gain_settling", lambda prob: payload()["gain_settling"])
    monkeypatch.setattr(engine, "peak_memory_mb", lambda *a: payload()["memory_N10000"])
    monkeypatch.setattr(engine, "time_ibis", lambda prob, N, n: (2e-2, 12, 9 * n * N))
    monkeypatch.setattr(engine, "step_budget", lambda prob, prof, N: dict(N=N))
    monkeypatch.setattr(engine, "bank_call_cost",
                        lambda prob, N, repeats: payload()["bank_call_N1000_ms"])
    out = engine.main_payload(True, progress=lambda m: None)
    assert OLD_KEYS | NEW_KEYS <= set(out) and out["repeats"] == engine.QUICK_REPEATS >= 3
    assert out["resamplings_first1000"] == 183
    at_100 = [k for k, N in calls[2:] if N == 100]
    assert at_100 == ["rbpf-working", "rbpf-paper", "qgrbpf"] * out["repeats"]
    base = [k for k, N in calls if ":" in k and not k.endswith(":step")]
    assert base[:4] == ["rbpf-working:numpy", "rbpf-working:filterpy"] * 2
    assert all(r["repeats"] == out["repeats"] for r in out["rows"])


def test_goals_say_met_or_the_factor_missing_and_withhold_busy_ratios():
    """Goal rows from the payload: a rate goal missed by 10x says 10x, a ratio goal met says met
    with no factor, an absent key says 'not measured', and a busy run withholds the ratios."""
    from railpaper.bench.report import goal_rows, goals_markdown
    quiet = payload()
    quiet["time_ratio_qgrbpf_over_rbpf_N1000"] = 0.8
    goals = {g["key"]: g for g in goal_rows(quiet)}
    paper = goals["steps_per_s_rbpf_lateral_N1000_paper_scheme"]
    assert paper["met"] is False and paper["factor_missing"] == pytest.approx(10.0)
    ratio = goals["time_ratio_qgrbpf_over_rbpf_N1000"]
    assert ratio["met"] is True and ratio["factor_missing"] is None
    assert goals["steps_per_s_ibis_lateral_N1000_first"]["why"] == "not measured in this run"
    busy = {g["key"]: g for g in goal_rows(payload(load=(5.0, 5.0, 5.0)))}
    assert busy["time_ratio_qgrbpf_over_rbpf_N1000"]["measured"] is None
    assert busy["steps_per_s_rbpf_lateral_N1000_paper_scheme"]["measured"] == 100.0
    page = goals_markdown(payload(load=(5.0, 5.0, 5.0)))
    assert WITHHELD in page and "10.0×" in page


def test_load_log_separates_the_bench_from_other_work():
    """Other work between two samples = machine busy CPU (/proc/stat) − the bench's own CPU, per
    second: a bench using 2 cores of a machine busy 2.1 cores leaves 0.1 (ratios printed), one
    busy 2.8 leaves 0.8 (withheld).  Without /proc/stat: the load average minus the 60-s
    exponential average of the bench's CPU use, 2(1 − e^-2) = 1.73 after 120 s at 2 cores."""
    import math

    from railpaper.timing import LoadLog
    for machine_busy, printed in ((2.1, True), (2.8, False)):
        clock, cpu = iter([0.0, 0.0, 120.0]), iter([0.0, 240.0])
        busy = iter([0.0, 120 * machine_busy])
        log = LoadLog(clock=lambda: next(clock), load=lambda: (2.05, 1.0, 1.0),
                      cpu=lambda: next(cpu), busy=lambda: next(busy))
        log.sample("start")
        log.sample("end")
        d = log.as_dict()
        assert d["other_max_cores"] == pytest.approx(machine_busy - 2.0, abs=1e-9)
        assert ratio_verdict(dict(cores=2, **d))[0] is printed
    clock, cpu = iter([0.0, 0.0, 120.0]), iter([0.0, 240.0])
    log = LoadLog(clock=lambda: next(clock), load=lambda: (2.05, 1.0, 1.0),
                  cpu=lambda: next(cpu), busy=lambda: None)
    log.sample("start")
    log.sample("end")
    own = 2 * (1 - math.exp(-2))
    assert log.as_dict()["load_samples"][-1]["other_cores"] == pytest.approx(2.05 - own, abs=1e-3)

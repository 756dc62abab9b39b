"""The Performance page's text comes from one bench payload; a busy machine is said so."""

from railpaper.pipeline.bench import PROFILE_LABELS, busy_note, findings_markdown, format_markdown


def payload(load=(0.5, 0.4, 0.3)):
    rows = [dict(problem="lateral-16", filter=f, engine="compiled", N=1000, steps=200,
                 steps_per_s=s, us_per_particle_step=1e6 / s / 1000)
            for f, s in (("rbpf-working", 237.0), ("rbpf-paper", 100.0), ("qgrbpf", 46.0))]
    return dict(
        steps_per_s_rbpf_lateral_N1000=237.0, steps_per_s_rbpf_lateral_N1000_paper_scheme=100.0,
        steps_per_s_rbpf_lateral_N1000_settled=690.0, settled_window={"skip": 2000, "steps": 1000},
        steps_per_s_qgrbpf_lateral_N1000=46.0, speedup_vs_filterpy_lateral_N1000=14.1,
        speedup_vs_filterpy_lateral_N1000_paper_scheme=9.0, speedup_vs_numpy_lateral_N1000=2.9,
        speedup_vs_numpy_lateral_N1000_paper_scheme=2.8, time_ratio_qgrbpf_over_rbpf_N1000=2.17,
        profile_N1000_ms={"kalman_bank_ms": 1.5, "zoh_all_particles_ms": 6.0,
                          "rest_of_paper_scheme_step_ms": 1.5},
        memory_N10000={"peak_rss_mb": 482.0, "particles_mb": 242.0, "bank_arrays_mb": 60.0},
        machine=dict(cores=2, cpu="x", python="3.11", numpy="2", blas="openblas", numba="0.6",
                     numba_threads=2, load_before=list(load), load_after=list(load)),
        quick=True, sizes={"working": 1000}, rows=rows)


def test_findings_quote_the_payload():
    text = findings_markdown(payload())
    assert "237 steps/s (0.24 × real time" in text and "690 steps/s" in text
    assert "14.1× (working scheme) and 9.0× (paper scheme)" in text
    assert "takes 9.0 ms" in text and f"{PROFILE_LABELS['zoh_all_particles_ms']} 6.00 ms (67%)" in text


def test_busy_machine_is_flagged_quiet_is_not():
    assert busy_note(payload((5.2, 3, 2))["machine"]).startswith("**The machine was busy**")
    note = busy_note(payload()["machine"])
    assert "quiet" in note and "busy" not in note
    assert "not recorded" in busy_note({"cores": 2})


def test_table_has_every_row():
    assert format_markdown(payload()).count("| lateral") == 0
    assert format_markdown(payload()).count("| compiled |") == 3


def test_benchmarks_load_by_file_path_without_touching_sys_path():
    import sys

    from railpaper.pipeline.bench import _load_benchmarks
    before = list(sys.path)
    engine = _load_benchmarks()
    assert sys.path == before
    assert engine.__file__.endswith("benchmarks/rbpf_engine.py")
    assert engine.FilterpyRBPF.__module__ == "benchmarks.filterpy_rbpf"
    assert _load_benchmarks() is engine

"""Chapter ``quasi-gaussian-rbpf``'s parameters (``SPEC``), its typed settings (``Settings``)
and its vocabulary: the two parameters, the filters compared and their display names and
colours."""

from __future__ import annotations

from railpaper.experiments.base import ChapterSpec, Parameter

P = Parameter


SPEC = ChapterSpec(
    name="quasi-gaussian-rbpf",
    title="Quasi-Gaussian RBPF versus RBPF for railway-vehicle parameters (authors lost in OCR)",
    paper="004_e1cb56090c839832.txt",
    notebook="quasi_gaussian_rbpf.ipynb",
    quick_sizes="500 particles, 200 steps, 61x61 grid, 50 Monte Carlo records, timing up to N=1000, "
                "8 paired timing repeats",
    notebook_requires={"timing": True},
    parameters=[
        P("a_true", -0.7, "float", "true parameter a of Eq. (20), 1"),
        P("b_true", 1.5, "float", "true parameter b of Eq. (20), 1"),
        P("q_var", 0.001, "float", "variance of each process-noise component w, 1", positive=True),
        P("r_var", 0.001, "float", "variance of each measurement-noise component e, 1",
          positive=True),
        P("p0_std", 0.05, "float", "initial state standard deviation (P0 = p0_std^2 I), 1",
          positive=True),
        P("n_particles", 1000, "int", "particles of every filter", quick=500, minimum=2),
        P("n_steps", 300, "int", "measurements per record", quick=200, minimum=2),
        P("a_min", -1.0, "float", "lower bound of the uniform prior on a, 1"),
        P("a_max", 0.4, "float", "upper bound of the uniform prior on a, 1"),
        P("b_min", 1.0, "float", "lower bound of the uniform prior on b, 1"),
        P("b_max", 2.8, "float", "upper bound of the uniform prior on b, 1"),
        P("liu_west_delta", 0.98, "float", "Liu-West discount factor delta of the RBPF move, 1",
          positive=True),
        P("ess_fraction", 0.5, "float", "working RBPF resamples when ESS < ess_fraction N, 1",
          positive=True),
        P("tempering_steps", 0, "int", "working RBPF likelihood tempering steps (0 = off)",
          minimum=0),
        P("weight_threshold", 0.01, "float",
          "Q-GRBPF drops likelihood weights below weight_threshold/N, 1", minimum=0.0),
        P("eq10_reading", "ratio", "str", "reading of Eq. (10) the illustrations show in full: "
          "'ratio' (importance ratio, corrected) or 'printed' (both are always computed)",
          changes_records=False),
        P("grid_size", 81, "int", "grid points per parameter of the exact posterior",
          quick=61, minimum=3),
        P("n_monte_carlo", 360, "int", "records (seeds) of the Monte Carlo study", quick=50,
          minimum=1, changes_records=False),
        P("record", 0, "int", "index of the main record (random streams (seed, record)); the "
          "Monte Carlo records are record+1, record+2 and so on", minimum=0,
          changes_records=False),
        P("timing", True, "bool", "measure computing times (false: a Monte Carlo sample of a "
          "sweep, which needs only the record's metrics)", changes_records=False),
        P("timing_particles", [100, 300, 1000, 3000, 10000], "list[int]",
          "particle counts of the computing-time comparison", quick=[100, 300, 1000],
          positive=True, changes_records=False),
        P("timing_steps", 100, "int", "steps timed per filter and particle count", quick=50,
          minimum=1, changes_records=False),
        P("timing_repeats", 3, "int", "repeats per timing of the curves (the fastest is kept)",
          quick=3, minimum=1, changes_records=False),
        P("timing_ratio_particles", 1000, "int", "particles of the paired timing repeats (the "
          "paper's N)", minimum=2, changes_records=False),
        P("timing_ratio_repeats", 20, "int", "paired timing repeats (RBPF and both Q-GRBPFs back "
          "to back) behind the time-ratio evidence", quick=8, minimum=1,
          changes_records=False),
        P("tolerance_to_truth", 0.05, "float",
          "paper-like convergence: first step with |estimate - truth| below this, 1",
          positive=True),
        P("short_horizon", 60, "int", "shortest horizon the paper's lost figures can have had "
          "(its RBPF converges at step 55, read to ±5): errors are also taken at this step "
          "(the last one if the record is shorter)",
          minimum=1),
        P("readings_records", 200, "int", "records per reading of the readings study (the "
          "exact posterior under five readings of the printed Q, R and P0, each read at five "
          "figure horizons; 0 skips it)", quick=40, minimum=0, changes_records=False),
        P("seed", 0, "int", "seed of records, initial particles and filters", minimum=0),
    ],
)
Settings = SPEC.settings_type


PARAMS = ("a", "b")


def true_values(settings: Settings) -> dict[str, float]:
    """The true value of each of :data:`PARAMS` (1)."""
    return {"a": settings.a_true, "b": settings.b_true}


#: Filters whose per-record metrics the table holds.
FILTERS = ("rbpf", "rbpf_working", "qgrbpf", "qgrbpf_printed")


#: The Q-GRBPF under each reading of Eq. (10): importance ratio (default), as printed.
QGRBPF_READINGS = ("qgrbpf", "qgrbpf_printed")


#: Suffix of the Q-GRBPF runs without the weight threshold (same record and random stream).
NO_THRESHOLD = "_nothreshold"


#: Display names of the filters (and of the exact posterior).
NAMES = {"posterior": "exact posterior", "rbpf": "RBPF, paper's scheme",
         "rbpf_working": "RBPF, working scheme", "qgrbpf": "Q-GRBPF, Eq. (10) as a ratio",
         "qgrbpf_printed": "Q-GRBPF, Eq. (10) as printed"}


#: Colour and line style of each filter.
STYLES = {"rbpf": ("C0", "-"), "rbpf_working": ("C2", "-."), "qgrbpf": ("C3", "-"),
          "qgrbpf_printed": ("C1", "--")}


#: The paper's steps: (parameter, filter) -> step (Section IV, Figs. 3-4).
PAPER_STEPS = {("a", "rbpf"): 55, ("b", "rbpf"): 53, ("a", "qgrbpf"): 4, ("b", "qgrbpf"): 4}

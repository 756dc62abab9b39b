"""Chapter ``partial-state-observer``'s parameters (``SPEC``): their defaults, quick sizes, units
and meaning; ``Settings``, the chapter's typed settings made from them."""

from __future__ import annotations

from railpaper.experiments.base import ChapterSpec, Parameter

SPEC = ChapterSpec(
    name="partial-state-observer",
    title="Partial-state observer of wheelset vibration (Zheng, Chai, Peng & Li 2016)",
    paper="000_2d1086b2834afcb9.txt",
    notebook="partial_state_observer.ipynb",
    quick_sizes="30 Monte Carlo seeds instead of 80; α sweep over 3 values instead of 6 "
                "(runs stay 8 s long: 2 s runs leave the speed trends undecided)",
    parameters=[
        Parameter("speeds_kmh", [60.0, 80.0, 120.0, 160.0], "list[float]",
                  "simulated speeds (paper: 60, 80, 120; Fig. 11 adds 160), km/h", positive=True),
        Parameter("duration_s", 8.0, "float", "simulated time per run (paper: 8 s), s",
                  positive=True),
        Parameter("dt_s", 1e-3, "float", "sample time of sensors and observer (paper: 1 ms), s",
                  positive=True),
        Parameter("lead_in_s", 1.0, "float",
                  "plant runs this long before the observer starts (settled start), s", minimum=0.0),
        Parameter("noise_fraction", 0.005, "float",
                  "sensor noise σ as a fraction of each channel's RMS (paper: 0.5 %)", minimum=0.0),
        Parameter("alpha_per_s", 20.0, "float",
                  "pole region of the paper's observer: slowest decay rate α, 1/s", positive=True),
        Parameter("beta", 2.0, "float", "pole region α ≤ −Re λ ≤ β α: ratio β (> 1)",
                  positive=True),
        Parameter("suspension_reading", "labels", "str",
                  "reading of Table 1's suspension rows for the illustrations: 'labels' (its "
                  "words: primary 2.14e6 N/m, 4.9e4 N·s/m) or 'symbols' (its symbols: primary "
                  "K_p = 2.535e6 N/m, C_p = 1.96e5 N·s/m); the evidence covers both",
                  changes_records=False),
        Parameter("alpha_sweep_per_s", [5.0, 10.0, 20.0, 40.0, 80.0, 160.0], "list[float]",
                  "values of α for the convergence-time sweep, 1/s",
                  quick=[10.0, 40.0, 160.0], positive=True, changes_records=False),
        Parameter("initial_error_m", 0.005, "float",
                  "initial error of every wheelset-displacement estimate, m"),
        Parameter("convergence_fraction", 0.05, "float",
                  "convergence threshold as a fraction of the RMS of the true z_w", positive=True),
        Parameter("error_window_start_s", 1.0, "float",
                  "errors are measured from this time on (paper: after 1 s), s", minimum=0.0),
        Parameter("track_class", 5, "int", "US FRA track class (1-6) of the vertical profile",
                  minimum=1),
        Parameter("wavelength_min_m", 1.524, "float", "shortest wavelength of the profile, m",
                  positive=True),
        Parameter("wavelength_max_m", 304.8, "float", "longest wavelength of the profile, m",
                  positive=True),
        Parameter("n_seeds", 80, "int", "Monte Carlo seeds (seed, seed+1, …), each at every "
                  "speed under both readings", quick=30, minimum=2, changes_records=False),
        Parameter("seed", 0, "int", "seed of the default run (track profile and sensor noise)",
                  minimum=0, changes_records=False),
    ],
)
Settings = SPEC.settings_type

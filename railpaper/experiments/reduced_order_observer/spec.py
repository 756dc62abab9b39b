"""Chapter ``reduced-order-observer``'s parameters (``SPEC``, its typed ``Settings``) and its
vocabulary: the readings of P0, the track band, the estimators compared and the noise levels of
the sensitivity table."""

from __future__ import annotations

from railpaper.experiments.base import ChapterSpec, Parameter
from railpaper.models import single_wheelset

SPEC = ChapterSpec(
    name="reduced-order-observer",
    title="Reduced-order observer of the wheel–rail force (Li, Zheng & Chai 2014)",
    paper="001_b49ad810fb7b323c.txt",
    notebook="reduced_order_observer.ipynb",
    quick_sizes="1 s simulated instead of 2 s; trend sweep over 4 speeds instead of 9; "
                "40 Monte Carlo seeds instead of 200",
    notebook_requires={"side_tables": True},
    parameters=[
        Parameter("speeds_kmh", [60.0, 100.0], "list[float]",
                  "speeds of the main runs (figures, time series, metrics), km/h", positive=True),
        Parameter("sweep_speeds_kmh", [40.0, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0],
                  "list[float]", "speeds of the trend figures, km/h",
                  quick=[40.0, 100.0, 160.0, 200.0], positive=True),
        Parameter("duration_s", 2.0, "float", "simulated time per run, s", quick=1.0, positive=True),
        Parameter("dt_s", 1e-4, "float", "time step of plant samples and observer (paper: 1e-4 s), s",
                  positive=True),
        Parameter("observer_poles", [-30.0, -40.0], "list[float]",
                  "poles of the observer error dynamics A22 − L·A12, 1/s (real, negative)"),
        Parameter("observer_form", "paper", "str",
                  "discretisation of observer (12): 'paper' (y, q held over a step, ZOH) or 'foh' "
                  "(y, q linear between samples)"),
        Parameter("plant", "linear", "str",
                  "plant that generates the truth: 'linear' (paper) or 'hertz' (nonlinear contact)"),
        Parameter("noise_fraction", 0.01, "float",
                  "sensor noise σ as a fraction of each measured channel's RMS (paper's D = 0.01)",
                  minimum=0.0),
        Parameter("track_noise_fraction", 0.0, "float",
                  "noise σ on the irregularity q given to the observer, fraction of its RMS",
                  minimum=0.0),
        Parameter("initial_error_m", 0.005, "float",
                  "initial error of the observer's wheelset displacement, m"),
        Parameter("track_class", 5, "int", "US FRA track class (1-6) of the vertical profile",
                  minimum=1),
        Parameter("convergence_fraction", 0.05, "float",
                  "convergence threshold as a fraction of the RMS of the true z_w", positive=True),
        Parameter("error_window_start_s", 0.5, "float",
                  "force errors are measured from this time to the end of the run, s", minimum=0.0),
        Parameter("p0_basis", "wheel", "str",
                  "reading of P0 in Eq. (3) for the single runs: 'wheel' (per-wheel static load, "
                  "two contacts) or 'wheelset' (the text: wheelset static load, one contact); the "
                  "Monte Carlo evidence always covers both"),
        Parameter("seed", 0, "int", "seed of the track profile and the sensor noise", minimum=0,
                  changes_records=False),     # a record's numbers follow its own seed only
        Parameter("mc_seeds", 200, "int",
                  "Monte Carlo seeds (seed, seed + 1 and so on; fewer than 1000) behind every claim verdict",
                  quick=40, minimum=2, changes_records=False),
        Parameter("side_tables", True, "bool",
                  "also compute the noise-sensitivity and linear-vs-Hertz tables and the Monte "
                  "Carlo evidence (sweep samples switch them off: they need only the main runs)",
                  changes_records=False),
    ],
)
Settings = SPEC.settings_type


#: Sensor-noise levels (fraction of channel RMS) of the noise-sensitivity table.
NOISE_SWEEP_FRACTIONS = (0.0, 1e-5, 1e-4, 1e-3, 1e-2)


#: Readings of the paper's P0 (Eq. 3), default (the chapter's) first; see ``single_wheelset``.
READINGS = single_wheelset.P0_BASES


#: Shortest and longest wavelengths of the FRA spectrum's validity range, m.
FRA_BAND_M = (1.524, 304.8)


#: The estimators compared, with their display names.
ESTIMATORS = {"observer": "paper's observer", "kalman": "Kalman filter",
              "smoother": "RTS smoother (offline)"}

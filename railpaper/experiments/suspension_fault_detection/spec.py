"""Chapter ``suspension-fault-detection``'s parameters (``SPEC``) and its vocabulary: the
detectors compared and the detection horizons.  No paper: an appendix of our own on paper 003's
lateral vehicle (``data/rbpf-parameter-estimation/parameters.toml``), its faults in
``data/suspension-fault-detection/faults.toml``."""

from __future__ import annotations

import numpy as np

from railpaper.experiments.base import ChapterSpec, Parameter
from railpaper.experiments.lateral_vehicle import TRACK_AND_SENSORS

P = Parameter
SPEC = ChapterSpec(
    name="suspension-fault-detection",
    title="How soon does a failed damper show in the data? Abrupt suspension faults",
    paper="",
    notebook="suspension_fault_detection.ipynb",
    quick_sizes="2 records per fault and speed (full: 20), 4 fault-free (full: 40)",
    parameters=[
        P("seed", 0, "int", "first record: fault records use seeds seed … seed + 299, fault-free "
          "ones seed + 300 … seed + 899; record seed is the one illustrated", minimum=0,
          changes_records=False),
        P("speeds_kmh", [300.0, 200.0], "list[float]", "vehicle speeds, km/h (the illustrated "
          "record is at the first)", positive=True),
        P("faults", "csaly_half,csaly_20,csaly_0,ksy_70,csaly_drift", "str",
          "comma-separated fault names of data/suspension-fault-detection/faults.toml"),
        P("extra_fault_parameter", "", "str", "one more abrupt fault of your own: the parameter "
          "(csy, lambda, kpy, ksy or csaly); empty = none"),
        P("extra_fault_factor", 0.5, "float", "… and the factor it is multiplied by, 1",
          positive=True),
        P("fault_time_s", -1.0, "float", "fault time of every record, s (on the prior's grid, "
          "data/suspension-fault-detection/faults.toml); -1 = drawn from the prior per record"),
        P("duration_s", 4.0, "float", "length of each record, s (it ends earlier where a "
          "wheelset reaches flange contact)", positive=True),
        P("dt_s", 0.005, "float", "sample time of the measurements and every detector, s "
          "(chapter 003 filters at 0.001 s; 200 Hz keeps this appendix within its time budget)",
          positive=True),
        P("truth_substeps", 10, "int", "truth steps per sample (truth dt = dt_s / this)",
          minimum=1),
        *TRACK_AND_SENSORS,
        P("records_per_fault", 20, "int", "records per fault and speed (Monte Carlo samples, at "
          "most 300)", quick=2, minimum=2, changes_records=False),
        P("fault_free_records", 40, "int", "fault-free records per speed: the first half sets "
          "each detector's threshold, the second half measures its false alarms (at most 600)",
          quick=4, minimum=4, changes_records=False),
        P("false_alarm_probability", 0.05, "float", "each detector's threshold: the probability "
          "of an alarm in a fault-free record's monitoring window (set on the first half of the "
          "fault-free records), 1", positive=True, changes_records=False),
        P("cusum_variance_ratio", 2.0, "float", "residual test: the growth of the whitened "
          "innovations' variance its CUSUM is tuned to, 1", positive=True),
        P("chi2_window_samples", 50, "int", "windowed chi-square test: the samples of whitened "
          "innovations it sums (50 = 0.25 s at 200 Hz), samples", minimum=1,
          changes_records=False),
        P("false_alarm_block_s", 0.5, "float", "mean times between false alarms beyond the "
          "running measured: the fault-free records' monitoring windows are cut into blocks of "
          "this length, and an exponential tail is fitted to the largest block maxima (one "
          "alarm per exceeding block), s", positive=True, changes_records=False),
        P("ladder_records_per_fault", 10, "int", "realism ladder: records per fault at "
          "ladder_speed_kmh on each rung beyond the ideal one (below 2: no ladder)", quick=0,
          minimum=0, changes_records=False),
        P("ladder_fault_free_records", 20, "int", "realism ladder: fault-free records on each "
          "rung (half set its thresholds, half check them; below 4: no ladder)", quick=0,
          minimum=0,
          changes_records=False),
        P("ladder_speed_kmh", 300.0, "float", "realism ladder: the speed of its records, km/h "
          "(one of speeds_kmh)", positive=True),
        P("bank_window_s", 0.1, "float", "bayes and glr: a change is looked for in the last "
          "this many seconds (the window W of the Shiryaev-Roberts sum and the GLR's maximum; "
          "their cost grows with it), s", positive=True),
    ],
)
#: The appendix's settings (a frozen dataclass of the parameters above).
Settings = SPEC.settings_type

#: The detectors compared, with their display names (paper 003's RBPF is not one: as a detector
#: it would need a jump move and a cloud covering a failed damper, and with them it is a
#: particle approximation of what ``bayes`` computes exactly; see the page).
DETECTORS = {"cusum": "variance CUSUM of the nominal filter's whitened innovations",
             "chi2": "windowed chi-square of the whitened innovations (nominal Kalman filter)",
             "glr": "window-limited GLR over any parameter, factor and change time",
             "bayes": "mixture Shiryaev-Roberts over any parameter, factor and change time",
             "oracle": "change posterior knowing the catalogue's faults and fault-time grid"}

#: The top of the critical-speed search, km/h (a model stable up to it is reported as "above").
CRITICAL_SEARCH_TOP_KMH = 600.0

#: Detection horizons after the fault, s.
WITHIN_S = (0.5, 1.0, 2.0)

#: Mean times between false alarms at which every detector's threshold is also set, h (a
#: railway monitor runs thousands of hours between false alarms).
MTBFA_TARGETS_H = (10.0, 100.0, 1000.0)

#: The realism ladder's rungs beyond the ideal one (the run's own sensors): cumulative changes
#: of the sensors, each a dict of settings (and, from ``track_unknown`` on, of the filters:
#: :data:`RUNGS_WITHOUT_TRACK`).  A channel is taken away by making its noise so
#: large that the filters give it no weight (100 m/s^2 against accelerations of about
#: 0.1-1 m/s^2; 10 rad/s against yaw rates of about 0.01 rad/s): the limit of removing it.
#: No published noise level is used: 0.01 rad/s is ten times chapter 003's gyro.
LADDER = {"no_axlebox_gyro_001": ("bogie and car-body accelerometers, gyro at 0.01 rad/s",
                                  {"noise_acc_wheelset_mps2": 100.0,
                                   "noise_yawrate_radps": 0.01}),
          "accelerometers_only": ("bogie and car-body accelerometers only",
                                  {"noise_acc_wheelset_mps2": 100.0,
                                   "noise_yawrate_radps": 10.0}),
          "track_unknown": ("bogie and car-body accelerometers only, the track input unknown",
                            {"noise_acc_wheelset_mps2": 100.0, "noise_yawrate_radps": 10.0})}
#: The rungs whose filters are not given the track input under each wheelset: they estimate it
#: with a shaping filter of the alignment spectrum at the speed and the wheelbase delay L/v
#: (:mod:`railpaper.models.lateral_unknown_track`).
RUNGS_WITHOUT_TRACK = ("track_unknown",)
#: Fault records per fault of the track-unknown rung in the run (the first of each fault's
#: seeds, with all the ladder's fault-free records; below 2: that rung is left out of the run).
#: Its filters carry 24 states and cost about 2.6 times as much per record, more than the
#: book's ten minutes pay for; the stored evidence holds the rung at the run's sizes instead
#: (:data:`STORED_RUNGS`).  Not a parameter: at other settings than the defaults the page shows
#: no track-unknown rung unless this is raised.
RUN_TRACK_UNKNOWN_RECORDS = 0
#: The rungs the stored evidence holds at the run's own sizes, beyond what the book's run
#: can afford (study ``stored_ladder``): the track-unknown rung, which the run's ladder holds
#: only with :data:`RUN_TRACK_UNKNOWN_RECORDS`, and the last rung, the same filters on a truth
#: with model error they do not know (:mod:`railpaper.models.lateral_model_error`: saturating
#: creep, a nonlinear and larger conicity, a series stiffness in the anti-yaw damper;
#: ``data/suspension-fault-detection/model_error.toml``).  Each: (description, sensor
#: settings, whether the truth has the model error); both estimate the track.
STORED_RUNGS = {"track_unknown": (LADDER["track_unknown"][0], LADDER["track_unknown"][1],
                                  False),
                "model_error": ("bogie and car-body accelerometers only, the track input "
                                "unknown, the truth with model error",
                                LADDER["track_unknown"][1], True)}
#: The detectors of the stored rungs: the run's and a model-free one, which sees the bogie
#: hunt, not a residual (:func:`~.detectors.hunting_rms`; every record carries its statistic,
#: the run's own evidence leaves it out: bringing it in means new CI bands).
STORED_DETECTORS = {**DETECTORS,
                    "hunting": "bogie lateral acceleration RMS over 100 m, band-passed at the "
                               "failed damper's hunting frequency (EN 14363's quantity)"}
#: The operating point the page's delay tables read, h between false alarms.
OPERATING_POINT_H = 100.0
#: The paired comparisons at the operating point (A, B): the Bayesian detector against each
#: other detector that does not know the fault, and the oracle against it (the value of
#: knowing the fault).
PAIRS = (("bayes", "glr"), ("bayes", "cusum"), ("bayes", "chi2"), ("oracle", "bayes"))

#: The ladder's operating point, h between false alarms.
LADDER_MTBFA_H = OPERATING_POINT_H

#: Mean times between false alarms at which the long running checks each tail model, h (an
#: hour of running counts about 100, 33, 10, 3 and 1 alarms at them).
RUNNING_CHECK_H = (0.01, 0.03, 0.1, 0.3, 1.0)
#: The p-value below which a check of the tail on the long running is not consistent.
RUNNING_CHECK_LEVEL = 0.05

#: The grid of the delay against mean time between false alarms picture, h.
MTBFA_CURVE_H = tuple(10.0 ** np.arange(-3.0, 4.01, 0.5))

__all__ = ["CRITICAL_SEARCH_TOP_KMH", "DETECTORS", "LADDER", "LADDER_MTBFA_H",
           "MTBFA_CURVE_H", "MTBFA_TARGETS_H", "OPERATING_POINT_H", "PAIRS",
           "RUNNING_CHECK_H", "RUNNING_CHECK_LEVEL", "RUNGS_WITHOUT_TRACK",
           "RUN_TRACK_UNKNOWN_RECORDS", "SPEC", "STORED_DETECTORS", "STORED_RUNGS", "Settings",
           "WITHIN_S"]

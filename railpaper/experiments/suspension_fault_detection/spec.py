"""Chapter ``suspension-fault-detection``'s parameters (``SPEC``) and its vocabulary: the
detectors compared and the detection horizons.  No paper: an appendix of our own on paper 003's
lateral vehicle (``data/rbpf-parameter-estimation/parameters.toml``), its faults in
``data/suspension-fault-detection/faults.toml``."""

from __future__ import annotations

from railpaper.experiments.base import ChapterSpec, Parameter
from railpaper.experiments.lateral_vehicle import TRACK_AND_SENSORS

P = Parameter
SPEC = ChapterSpec(
    name="suspension-fault-detection",
    title="How soon does a failed damper show in the data? Abrupt suspension faults",
    paper="",
    notebook="suspension_fault_detection.ipynb",
    quick_sizes="3 records per fault and speed (full: 30), 6 fault-free (full: 60); RBPF with 40 "
                "particles (full: 100) on 2 records per fault (full: 12) and 2 fault-free (full: "
                "16)",
    parameters=[
        P("seed", 0, "int", "first record: fault records use seeds seed … seed + 299, fault-free "
          "ones seed + 300 … seed + 899; record seed is the one illustrated", minimum=0,
          changes_records=False),
        P("speeds_kmh", [300.0, 200.0], "list[float]", "vehicle speeds, km/h (the RBPF runs at "
          "the first)", positive=True),
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
        P("records_per_fault", 30, "int", "records per fault and speed (Monte Carlo samples, at "
          "most 300)", quick=3, minimum=2, changes_records=False),
        P("fault_free_records", 60, "int", "fault-free records per speed: the first half sets "
          "each detector's threshold, the second half measures its false alarms (at most 600)",
          quick=6, minimum=4, changes_records=False),
        P("false_alarm_probability", 0.05, "float", "each detector's threshold: the probability "
          "of an alarm in a fault-free record's monitoring window (set on the first half of the "
          "fault-free records), 1", positive=True, changes_records=False),
        P("cusum_variance_ratio", 2.0, "float", "residual test: the growth of the whitened "
          "innovations' variance its CUSUM is tuned to, 1", positive=True),
        P("chi2_window_samples", 50, "int", "windowed chi-square test: the samples of whitened "
          "innovations it sums (50 = 50 ms at 1 kHz), samples", minimum=1,
          changes_records=False),
        P("rbpf_records_per_fault", 12, "int", "records per fault (the first ones, first speed) "
          "also filtered by the RBPF", quick=2, minimum=2, changes_records=False),
        P("rbpf_fault_free_records", 16, "int", "fault-free records (first speed) filtered by "
          "the RBPF: half set its threshold, half measure its false alarms", quick=2, minimum=2,
          changes_records=False),
        P("n_particles", 100, "int", "RBPF particles", quick=40, minimum=2),
        P("paper_delta", 0.98, "float", "Liu-West delta of the RBPF (paper 003's scheme), 1",
          positive=True),
        P("prior_low", 0.5, "float", "RBPF's initial cloud: lower edge, fraction of the nominal "
          "value", positive=True),
        P("prior_high", 1.7, "float", "RBPF's initial cloud: upper edge, fraction of the nominal "
          "value", positive=True),
    ],
)
#: The appendix's settings (a frozen dataclass of the parameters above).
Settings = SPEC.settings_type

#: The detectors compared, with their display names.
DETECTORS = {"residual": "residual CUSUM (nominal Kalman filter)",
             "chi2": "windowed chi-square of the whitened innovations (nominal Kalman filter)",
             "rbpf": "RBPF estimate leaves its band (paper 003)",
             "exact": "exact change posterior (Kalman bank over fault times)"}

#: The parameters the RBPF tracks (the others stay at their nominal values).
TRACKED = ("ksy", "csaly")

#: Detection horizons after the fault, s.
WITHIN_S = (0.5, 1.0, 2.0)

__all__ = ["DETECTORS", "SPEC", "Settings", "TRACKED", "WITHIN_S"]

"""The faults of the appendix: the catalogue (``data/suspension-fault-detection/faults.toml``),
each fault's schedule θ(t) over a record, the prior grid of fault times, and the critical
(hunting) speed of the vehicle once a fault has developed — the speed an engineer must stay
below after it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from railpaper.data import DataError, load_quantities, read_toml
from railpaper.experiments.suspension_fault_detection.result import NO_FAULT, Fault
from railpaper.experiments.suspension_fault_detection.spec import CRITICAL_SEARCH_TOP_KMH, SPEC
from railpaper.models import lateral_16state, lateral_model_error
from railpaper.models.lateral_truth import WheelRail
from railpaper.paths import DATA_DIR

FAULTS_FILE = DATA_DIR / SPEC.name / "faults.toml"
#: The catalogue's scalar settings (value, unit, source each).
SETTINGS = ("drift_s", "drift_pieces", "fault_time_first_s", "fault_time_last_s",
            "fault_time_spacing_s", "p_no_fault", "flange_clearance_m")
KINDS = ("abrupt", "drift")
MODEL_ERROR_FILE = DATA_DIR / SPEC.name / "model_error.toml"
#: The contact nonlinearities of the ladder's last rung: chapter 003's truth plant's
#: (``data/rbpf-parameter-estimation/mismatch.toml``).
CONTACT_FILE = DATA_DIR / "rbpf-parameter-estimation" / "mismatch.toml"
#: Speeds searched for the critical speed, km/h.
CRITICAL_SEARCH_KMH = np.arange(100.0, CRITICAL_SEARCH_TOP_KMH + 1e-9, 2.5)


def catalogue(path=FAULTS_FILE) -> tuple[dict[str, Fault], dict[str, float]]:
    """The faults by name, and the settings (:data:`SETTINGS`, SI units) of the data file (a
    dict, ``fault_settings`` in this package: not the appendix's ``Settings``)."""
    document = read_toml(path)
    faults = {}
    for name, row in document.get("faults", {}).items():
        fault = Fault(name=name, parameter=row.get("parameter", ""),
                      factor=float(row.get("factor", -1.0)), kind=row.get("kind", ""),
                      label=row.get("label", name))
        if fault.parameter not in lateral_16state.PARAM_NAMES or fault.kind not in KINDS \
                or not fault.factor >= 0 or not row.get("source"):
            raise DataError(f"{path}: fault '{name}' needs parameter (one of "
                            f"{', '.join(lateral_16state.PARAM_NAMES)}), factor >= 0, "
                            "kind (abrupt or drift) and source")
        faults[name] = fault
    quantities = load_quantities(path, SETTINGS, section="settings")
    return faults, {k: float(q.value) for k, q in quantities.items()}


@dataclass(frozen=True)
class ModelError:
    """What the ladder's last rung's truth has that the filters' model does not
    (:mod:`railpaper.models.lateral_model_error`).

    Attributes
    ----------
    wheel_rail : WheelRail
        Saturating creep and the nonlinear rolling-radius difference (chapter 003's).
    conicity_factor : float
        The truth's small-amplitude conicity over the filters' nominal one, 1.
    series_stiffness_N_per_m : float
        The anti-yaw dampers' series stiffness, N/m.
    """

    wheel_rail: WheelRail
    conicity_factor: float
    series_stiffness_N_per_m: float

    def truth_theta(self, theta: np.ndarray) -> np.ndarray:
        """The truth's θ: the filters' with the conicity scaled."""
        out = np.array(theta, float)
        out[lateral_16state.PARAM_NAMES.index("lambda")] *= self.conicity_factor
        return out


def model_error(path=MODEL_ERROR_FILE, contact_path=CONTACT_FILE) -> ModelError:
    """The last rung's :class:`ModelError` from its data files."""
    own = load_quantities(path, ("conicity_factor", "series_stiffness"))
    contact = load_quantities(contact_path)
    wheel_rail = WheelRail(float(contact["friction_coefficient"].value),
                           float(contact["wheel_load"].value),
                           float(contact["conicity_length_scale"].value))
    return ModelError(wheel_rail, float(own["conicity_factor"].value),
                      float(own["series_stiffness"].value))


def bayes_factors(path=FAULTS_FILE) -> np.ndarray:
    """The post-fault factors of the detectors that do not know the fault (``[bayes] factors``
    of the data file: fractions of nominal, each applied to each model parameter)."""
    table = read_toml(path).get("bayes", {})
    factors = np.asarray(table.get("factors", []), float)
    if factors.ndim != 1 or not factors.size or np.any(factors < 0) \
            or np.any(np.isclose(factors, 1.0)) or not table.get("reason"):
        raise DataError(f"{path}: [bayes] needs 'factors' (a list of fractions of nominal, none "
                        "of them 1) and a 'reason'")
    return factors


def fault_times_s(fault_settings: dict) -> np.ndarray:
    """The prior's grid of fault times, s (uniform over it)."""
    first, last, step = (fault_settings[k] for k in ("fault_time_first_s", "fault_time_last_s",
                                               "fault_time_spacing_s"))
    return first + step * np.arange(int(round((last - first) / step)) + 1)


def factor_at(fault: Fault, fault_settings: dict, time_s: np.ndarray, fault_time_s: float
              ) -> np.ndarray:
    """The faulted parameter's value at ``time_s``, fraction of nominal (1 before the fault)."""
    t = np.asarray(time_s, float) - fault_time_s
    if fault.kind == "abrupt":
        return np.where(t >= 0, fault.factor, 1.0)
    ramp = np.clip(t / fault_settings["drift_s"], 0.0, 1.0)
    return 1.0 + (fault.factor - 1.0) * ramp


def schedule(fault: Fault | None, fault_settings: dict, theta: np.ndarray, fault_step: int,
             fine_steps: int, dt_fine_s: float) -> tuple[list[np.ndarray], list[int]]:
    """θ piecewise constant over the truth's fine steps: ``(thetas, starts)`` for
    :func:`railpaper.models.lateral_16state.simulate_truth_schedule`.  An abrupt fault changes θ
    after fine step ``fault_step``; a drift moves in ``drift_pieces`` equal pieces, each held at
    the ramp's value at its middle."""
    if fault is None:
        return [theta], [0]
    j = lateral_16state.PARAM_NAMES.index(fault.parameter)
    thetas, starts = [theta], [0]
    if fault.kind == "abrupt":
        changed = theta.copy()
        changed[j] *= fault.factor
        return thetas + [changed], starts + [min(fault_step, fine_steps)]
    pieces = int(fault_settings["drift_pieces"])
    span = fault_settings["drift_s"] / dt_fine_s
    for i in range(pieces):
        start = fault_step + int(round(i * span / pieces))
        if start >= fine_steps:
            break
        changed = theta.copy()
        changed[j] *= 1.0 + (fault.factor - 1.0) * (i + 0.5) / pieces
        thetas.append(changed)
        starts.append(start)
    if fault_step + span < fine_steps:                   # the end value, held after the drift
        changed = theta.copy()
        changed[j] *= fault.factor
        thetas.append(changed)
        starts.append(fault_step + int(round(span)))
    return thetas, starts


def critical_speeds(fixed: dict, theta: np.ndarray, faults: list[Fault]) -> pd.DataFrame:
    """The model's critical speed, km/h, fault-free and after each fault has fully developed
    (NaN: stable up to the search's end, :data:`CRITICAL_SEARCH_KMH`)."""
    rows = []
    for fault in [None] + list(faults):
        changed = theta.copy()
        if fault is not None:
            changed[lateral_16state.PARAM_NAMES.index(fault.parameter)] *= fault.factor
        _, v = lateral_16state.critical_speed(fixed, changed, CRITICAL_SEARCH_KMH / 3.6)
        rows.append({"fault": NO_FAULT if fault is None else fault.name,
                     "label": "fault-free" if fault is None else fault.label,
                     "critical_speed_kmh": v * 3.6 if v > 0 else np.nan})
    return pd.DataFrame(rows)



#: The series stiffness's multiples at which :func:`model_error_summary` gives the critical
#: speed: its sensitivity to a value with no measured source.
SERIES_STIFFNESS_RATIOS = (0.5, 1.0, 2.0)


def model_error_summary(fixed: dict, theta: np.ndarray, model_error: ModelError) -> dict:
    """What the page says of the truth with model error, SI units: ``friction``,
    ``conicity_scale_m``, ``conicity`` (the truth's) and ``conicity_filters``,
    ``series_stiffness_N_per_m``, ``maxwell_time_s`` (C_saly / K_s at the nominal damping), and
    the linearised truth's critical speed, km/h, fault-free and with the anti-yaw damping halved
    (``critical_speed_kmh``, ``critical_speed_csaly_half_kmh``; NaN: stable to the search's
    end), and fault-free at the series stiffness times each of :data:`SERIES_STIFFNESS_RATIOS`
    (``critical_speed_kmh_stiffness_x<ratio>``) and with a pure damper
    (``critical_speed_kmh_pure_damper``)."""
    truth = model_error.truth_theta(theta)
    j_lambda, j_csaly = (lateral_16state.PARAM_NAMES.index(n) for n in ("lambda", "csaly"))
    half = truth.copy()
    half[j_csaly] *= 0.5
    speeds = {}
    for key, th in (("critical_speed_kmh", truth), ("critical_speed_csaly_half_kmh", half)):
        _, v = lateral_model_error.critical_speed(fixed, th, CRITICAL_SEARCH_KMH / 3.6,
                                                  model_error.series_stiffness_N_per_m)
        speeds[key] = v * 3.6 if v > 0 else np.nan
    for ratio in SERIES_STIFFNESS_RATIOS:           # how much the stiffness's value matters
        _, v = lateral_model_error.critical_speed(
            fixed, truth, CRITICAL_SEARCH_KMH / 3.6, ratio * model_error.series_stiffness_N_per_m)
        speeds[f"critical_speed_kmh_stiffness_x{ratio:g}"] = v * 3.6 if v > 0 else np.nan
    _, v = lateral_16state.critical_speed(fixed, truth, CRITICAL_SEARCH_KMH / 3.6)
    speeds["critical_speed_kmh_pure_damper"] = v * 3.6 if v > 0 else np.nan
    return {"friction": model_error.wheel_rail.friction,
            "conicity_scale_m": model_error.wheel_rail.conicity_scale_m,
            "conicity": float(truth[j_lambda]), "conicity_filters": float(theta[j_lambda]),
            "series_stiffness_N_per_m": model_error.series_stiffness_N_per_m,
            "maxwell_time_s": float(truth[j_csaly] / model_error.series_stiffness_N_per_m),
            **speeds}


__all__ = ["CONTACT_FILE", "FAULTS_FILE", "MODEL_ERROR_FILE", "ModelError",
           "SERIES_STIFFNESS_RATIOS", "SETTINGS", "bayes_factors", "catalogue", "critical_speeds",
           "factor_at", "fault_times_s", "model_error", "model_error_summary", "schedule"]

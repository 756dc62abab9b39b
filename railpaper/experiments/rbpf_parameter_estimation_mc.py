"""Monte Carlo statistics of the ``rbpf-parameter-estimation`` chapter's toy (paper 003, Eq. 18).

The chapter's notebook filters ``mc_seeds`` further toy records as a sweep (each sample is the
chapter's ``run`` with ``toy_seeds = 1``, ``lateral = false``); these functions turn the sweep's
rows (and the main run's records) into EKF event rates with exact binomial intervals and into the
``mc_*`` metrics that join the chapter's checked metrics.
"""

from __future__ import annotations

import pandas as pd
from scipy.stats import beta

EVENTS = (("diverged", "ekf_diverged", "divergence"), ("biased", "ekf_biased", "biased"))


def sweep_seeds_and_params(params: dict) -> tuple[range, dict]:
    """Seeds of the Monte Carlo toy records (after the main run's ``toy_seeds`` records, so none
    repeats one of them) and the parameters of every sample (one toy record, no lateral part)."""
    first = params["seed"] + params["toy_seeds"]
    return range(first, first + params["mc_seeds"]), dict(params, toy_seeds=1, lateral=False)


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper–Pearson) interval of a proportion from ``k`` events in ``n`` trials; with
    no event the upper end is ``1 − ((1 − level)/2)^(1/n)``."""
    if not 0 <= k <= n or n < 1:
        raise ValueError(f"binomial_interval needs 0 <= k <= n, n >= 1; got k={k}, n={n}")
    a = (1.0 - level) / 2.0
    return (float(beta.ppf(a, k, n - k + 1)) if k > 0 else 0.0,
            float(beta.ppf(1.0 - a, k + 1, n - k)) if k < n else 1.0)


def ekf_event_rates(samples: pd.DataFrame, toy_stats: pd.DataFrame) -> pd.DataFrame:
    """EKF divergence / bias rates per initial condition, from the sweep's ``ok`` samples alone
    and from them together with the main run's records (``toy_stats``: columns init,
    ekf_diverged, ekf_biased); a sample counts as an event when its record's fraction is > 0.5."""
    _require_samples(samples)
    rows = []
    for ic in (1, 2):
        main = toy_stats[toy_stats.init == ic]
        for event, column, _ in EVENTS:
            swept = samples[f"toy_ekf_{event}_fraction_init{ic}"] > 0.5
            for source, hits in (("sweep", swept),
                                 ("sweep + main run",
                                  pd.concat([swept, main[column].astype(bool)]))):
                k, n = int(hits.sum()), len(hits)
                low, high = binomial_interval(k, n)
                rows.append(dict(init=ic, event=event, records=source, count=k, n=n,
                                 fraction=k / n, ci95_low=low, ci95_high=high))
    return pd.DataFrame(rows)


def monte_carlo_metrics(sweep: pd.DataFrame) -> dict:
    """The ``mc_*`` metrics from a sweep's rows (all statuses): failed samples; EKF divergence
    and bias fractions; median and 90 % quantile of the RBPFs' final errors."""
    ok = sweep[sweep.status == "ok"]
    _require_samples(ok, sweep)
    metrics = {"mc_failed_samples": int((sweep.status != "ok").sum())}
    for ic in (1, 2):
        for event, _, name in EVENTS:
            hits = ok[f"toy_ekf_{event}_fraction_init{ic}"] > 0.5
            metrics[f"mc_ekf_{name}_fraction_ic{ic}"] = float(hits.sum() / len(hits))
    for ic in (1, 2):
        err = ok[f"toy_final_abs_error_max_rbpf_init{ic}"]
        metrics[f"mc_rbpf_final_abs_error_median_ic{ic}"] = float(err.median())
        metrics[f"mc_rbpf_final_abs_error_p90_ic{ic}"] = float(err.quantile(0.9))
        metrics[f"mc_rbpf_working_final_abs_error_median_ic{ic}"] = float(
            ok[f"toy_rbpf_working_error_median_init{ic}"].median())
    return metrics


def _require_samples(ok: pd.DataFrame, sweep: pd.DataFrame | None = None) -> None:
    if len(ok) == 0:
        first = "" if sweep is None or not len(sweep) else f"; first error: {sweep.error.iloc[0]}"
        raise ValueError(f"no Monte Carlo sample of the toy finished ok{first}")


__all__ = ["binomial_interval", "ekf_event_rates", "monte_carlo_metrics",
           "sweep_seeds_and_params"]

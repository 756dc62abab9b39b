"""Part 1 of the ``rbpf-parameter-estimation`` chapter: paper 003's Eq. (18) toy on many records.

The RBPF exactly as the paper's Steps 1–2.6 (``scheme="paper"``, prior uniform on the initial
condition ± ``toy_prior_halfwidth``), our working scheme beside it (no claim reads it), and an
augmented-state EKF, each from the paper's initial conditions 1 = (0, 0, 0, 0) and
2 = (−0.26, 1, 0.24, −0.5).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.estimators.ekf import eq18_model, run_augmented_ekf
from railpaper.estimators.rbpf import run_rbpf
from railpaper.experiments import rbpf_parameter_estimation_mc as mc
from railpaper.models.linear_toys import EQ18_G, eq18_system, simulate_eq18

TOY_INITS = {1: np.zeros(4), 2: np.array([-0.26, 1.0, 0.24, -0.5])}
EKF_BOUND = 1e3       # |x_j| above this: the toy EKF has diverged; its error then counts as this


def run_toy(p: dict) -> dict:
    """Eq. (18): RBPF (paper scheme; our working scheme beside it, which no claim reads) and
    augmented EKF from both initial conditions on records ``seed`` … ``seed + toy_seeds − 1``.

    Returns ``truth``, ``table`` (the first record's estimates per step) and ``stats``: one row
    per (record, initial condition) with final max |error| over x1..x4, converged flags
    (final max |error| <= ``toy_bias_tol``; for the EKF also not diverged) and the settle steps
    of :func:`~railpaper.experiments.rbpf_parameter_estimation_mc.settle_step` (steps,
    ``toy_steps + 1`` = never).
    """
    truth = np.array([p["toy_x1"], p["toy_x2"], p["toy_x3"], p["toy_x4"]])
    v, tol, K = p["toy_noise_var"], p["toy_bias_tol"], p["toy_steps"]
    system = eq18_system(v, v)
    Q, R = v * EQ18_G @ EQ18_G.T, np.array([[v]])
    series, stats = {}, []

    def err(theta):                                       # max |error| over x_j per step
        e = np.nan_to_num(np.abs(theta - truth).max(axis=1), nan=EKF_BOUND)
        return np.minimum(e, EKF_BOUND)

    for i in range(p["toy_seeds"]):
        rng = np.random.default_rng(p["seed"] + i)
        sim = simulate_eq18(truth, v, v, K, rng)
        for ic, init in TOY_INITS.items():
            hw = p["toy_prior_halfwidth"]
            theta0 = rng.uniform(init - hw, init + hw, (p["toy_particles"], 4))
            rb = run_rbpf(system, sim.y, theta0, np.zeros(2), np.eye(2), rng, u=sim.u,
                          scheme="paper", delta=p["paper_delta"])
            rw = run_rbpf(system, sim.y, theta0, np.zeros(2), np.eye(2), rng, u=sim.u,
                          scheme="working", delta=p["working_delta"],
                          ess_fraction=p["ess_fraction"],
                          tempering_steps=p["toy_tempering_steps"])
            ek = run_augmented_ekf(eq18_model, sim.y, init, np.zeros(2), np.eye(2), 1.0, Q, R,
                                   p["toy_ekf_q_theta"], u=sim.u, divergence_bound=EKF_BOUND)
            e_rb, e_rw, e_ek = err(rb.theta_mean), err(rw.theta_mean), err(ek.theta)
            if ek.diverged:
                e_ek[ek.diverged_step - 1:] = EKF_BOUND
            stats.append(dict(seed=p["seed"] + i, init=ic, rbpf_err_max=e_rb[-1],
                              rbpf_working_err_max=e_rw[-1], ekf_err_max=e_ek[-1],
                              ekf_diverged=ek.diverged,
                              ekf_converged=not ek.diverged and e_ek[-1] <= tol,
                              rbpf_converged=bool(e_rb[-1] <= tol),
                              rbpf_settle=mc.settle_step(e_rb, tol),
                              ekf_settle=mc.settle_step(e_ek, tol)))
            if i == 0:
                series[f"rbpf_init{ic}"] = rb.theta_mean
                series[f"rbpfworking_init{ic}"] = rw.theta_mean
                series[f"ekf_init{ic}"] = ek.theta
    table = pd.DataFrame({"step": np.arange(1, K + 1)})
    for key, arr in series.items():
        for j in range(4):
            table[f"x{j + 1}_{key}"] = arr[:, j]
    return dict(truth=truth, table=table, stats=pd.DataFrame(stats))

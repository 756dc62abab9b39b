"""Benchmark of the RBPF engine on paper 003's lateral model (16 states, 5 channels, 1 kHz).

Every number is measured in this process on the same simulated record (the chapter's
``simulate_lateral`` at its default settings), against baselines run here too:

* ``compiled``: the library's RBPF / Q-GRBPF (numba Kalman bank + balanced Taylor ZOH);
* ``numpy``: the same filters on the textbook path — stacked ``scipy.linalg.expm`` + numpy
  predict / Joseph update (``engine="numpy"``);
* ``filterpy``: :class:`railpaper.bench.filterpy_rbpf.FilterpyRBPF`, one filterpy filter per particle.

How it is measured (:mod:`railpaper.timing`): filters that are compared are timed interleaved,
A B C A B C …, :data:`REPEATS` alternations (:data:`QUICK_REPEATS` at quick sizes), each a fresh
filter on the same steps with the same seed; a rate is the median over the alternations with its min–max spread, a ratio the median of
the per-alternation ratios with theirs.  The 1-minute load average is sampled before, between
the blocks and after; :mod:`railpaper.bench.report` prints no ratio from a run whose load
exceeded the core count.  The estimates of the baselines are compared with ours
(``max_rel_theta_diff``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np

from railpaper.bench.filterpy_rbpf import FilterpyRBPF
from railpaper.bench.flops import step_budget
from railpaper.discretise import zoh
from railpaper.engine import (LinearGaussianBatch, QuasiGaussianRBPF, RaoBlackwellisedPF,
                              kalman_run, run_ibis)
from railpaper.experiments.lateral_vehicle import RecordSettings, prior_centre
from railpaper.experiments.rbpf_parameter_estimation import experiment
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.experiments.rbpf_parameter_estimation.posterior import MIN_MOVES, PROPOSAL
from railpaper.experiments.rbpf_parameter_estimation.spec import Settings
from railpaper.models import lateral_16state
from railpaper.timing import LoadLog, interleaved, machine, paired_ratio, rates, summary

REPEATS = 5                    # alternations of every interleaved comparison (full sizes)
QUICK_REPEATS = 3              # at quick sizes: the book's Performance page, within its budget
FIRST_STEPS = 1000             # steps 1..FIRST_STEPS: the working scheme's start-up
MAX_CHUNK = 32                 # RaoBlackwellisedPF.steps' default chunk of the working scheme
PROFILE_WARMUP = 40            # steps of a throwaway paper-scheme filter before the profiles
PROFILE_SKIP = 5               # the profiled filter's untimed first steps


def lateral_problem(n_steps: int, seed: int = 0) -> dict:
    """The chapter's default lateral record (n_steps at 1 kHz) and the filter's model; the
    chapter's settings under ``"settings"``."""
    settings = experiment.SPEC.resolve({"n_steps": max(n_steps, 400)}, False)
    fixed, theta = study.vehicle()
    data = study.simulate_lateral(RecordSettings.of(settings), fixed, theta, seed)
    Q, R = study.filter_noise(fixed, theta, RecordSettings.of(settings), data.du_var_m2ps2)
    v = settings.speed_kmh / 3.6
    A0, Ak = lateral_16state.affine_terms(fixed, v)
    fast = lateral_16state.lateral_system(fixed, v, settings.dt_s, Q, R,
                                          theta_ref=prior_centre(theta, settings.prior_low,
                                                                 settings.prior_high))

    def textbook(th):                          # stacked scipy expm: the straightforward path
        A = lateral_16state.a_of_theta(A0, Ak, th)
        F, G = zoh(A, lateral_16state.input_matrix(), settings.dt_s)
        return LinearGaussianBatch(F, Q, lateral_16state.measurement_matrix(A), R, G)

    return dict(settings=settings, theta=theta, y=data.y, u=data.u_mps, Q=Q, R=R, A0=A0, Ak=Ak,
                systems={"compiled": fast, "numpy": textbook})


def scheme_options(settings: Settings, scheme: str) -> dict:
    if scheme == "paper":
        return dict(scheme="paper", delta=settings.paper_delta)
    return dict(scheme="working", delta=settings.working_delta,
                ess_fraction=settings.ess_fraction, tempering_steps=settings.tempering_steps,
                log_mask=np.ones(5, bool))


def make_filter(prob: dict, kind: str, N: int, seed: int = 11):
    """kind: 'rbpf-working', 'rbpf-paper', 'qgrbpf' (+ ':numpy' or ':filterpy' for baselines)."""
    name, _, engine = kind.partition(":")
    engine = engine or "compiled"
    rng = np.random.default_rng(seed)
    settings, theta = prob["settings"], prob["theta"]
    theta0 = theta * rng.uniform(settings.prior_low, settings.prior_high, (N, 5))
    x0, P0 = np.zeros(lateral_16state.N_STATES), 1e-10 * np.eye(lateral_16state.N_STATES)
    if name == "qgrbpf":
        return QuasiGaussianRBPF(prob["systems"][engine], theta0, x0, P0, rng, engine=engine)
    opts = scheme_options(settings, name.split("-")[1])
    if engine == "filterpy":
        return FilterpyRBPF(prob["A0"], prob["Ak"], lateral_16state.input_matrix(),
                            lateral_16state.measurement_matrix, settings.dt_s, prob["Q"],
                            prob["R"], theta0, x0, P0, rng, **opts)
    return RaoBlackwellisedPF(prob["systems"][engine], theta0, x0, P0, rng, engine=engine,
                              **opts)


def time_filter(prob: dict, kind: str, N: int, n_steps: int, per_step: bool = False,
                skip: int = 0) -> tuple[float, np.ndarray]:
    """Seconds per step over steps skip+1..skip+n_steps of the record (the first ``skip``
    steps run untimed), and the θ estimates (n_steps, 5).

    The library's RBPF runs through ``steps`` (the working scheme then runs its Kalman bank
    over chunks of steps between resampling events: estimates lag by at most 32 samples);
    ``per_step=True`` calls ``step`` once per measurement (lag: none).
    """
    filt = make_filter(prob, kind, N)
    if skip:
        filt.steps(prob["y"][:skip], prob["u"][:skip])
    Y, U = prob["y"][skip:skip + n_steps], prob["u"][skip:skip + n_steps]
    t0 = time.perf_counter()
    if hasattr(filt, "steps") and not per_step:
        est = np.array([o.theta_mean for o in filt.steps(Y, U)])
    else:
        est = np.empty((n_steps, 5))
        for k in range(n_steps):
            out = filt.step(Y[k], U[k])
            est[k] = out if isinstance(out, np.ndarray) else out.theta_mean
    return (time.perf_counter() - t0) / n_steps, est


def working_timeline(prob: dict, N: int, skip: int, steps: int) -> tuple[float, float, int]:
    """One working-scheme run at N: seconds per step over steps 1..FIRST_STEPS, over steps
    skip+1..skip+steps (settled; the steps between run untimed), and the resamplings among
    steps 1..FIRST_STEPS."""
    filt = make_filter(prob, "rbpf-working", N)
    Y, U = prob["y"], prob["u"]
    t0 = time.perf_counter()
    outputs = filt.steps(Y[:FIRST_STEPS], U[:FIRST_STEPS])
    first = (time.perf_counter() - t0) / FIRST_STEPS
    filt.steps(Y[FIRST_STEPS:skip], U[FIRST_STEPS:skip])
    t0 = time.perf_counter()
    filt.steps(Y[skip:skip + steps], U[skip:skip + steps])
    settled = (time.perf_counter() - t0) / steps
    return first, settled, int(sum(o.resampled for o in outputs))


def time_ibis(prob: dict, N: int, n_steps: int, seed: int = 11) -> tuple[float, int, int]:
    """IBIS (the chapter's exact-posterior scheme, :func:`railpaper.engine.ibis.run_ibis`
    with the chapter's proposal, prior box and state prior) over steps 1..n_steps at N: seconds
    per step, resampling events, Kalman filter steps run (moves re-run the whole history)."""
    settings, theta = prob["settings"], prob["theta"]
    t0 = time.perf_counter()
    run = run_ibis(prob["systems"]["compiled"], prob["y"][:n_steps], settings.prior_low * theta,
                   settings.prior_high * theta, np.zeros(lateral_16state.N_STATES),
                   1e-10 * np.eye(lateral_16state.N_STATES),
                   np.random.default_rng(seed), u=prob["u"][:n_steps], n_particles=N,
                   proposal=PROPOSAL, min_moves=MIN_MOVES)
    return ((time.perf_counter() - t0) / n_steps, len(run.resample_steps),
            int(run.n_filter_steps))


def paper_filter_after(prob: dict, N: int, steps: int):
    """A paper-scheme filter at N that has run the record's first ``steps`` steps."""
    filt = make_filter(prob, "rbpf-paper", N)
    for k in range(steps):
        filt.step(prob["y"][k], prob["u"][k])
    return filt


def profiled_paper_filter(prob: dict, N: int):
    """The filter the profiles time from step PROFILE_SKIP + 1 on, made after PROFILE_WARMUP
    steps of a throwaway one: run right after the baselines, the first steps of a new filter
    were 3x slow in one part or another (bank or ZOH), and a profile of them was wrong by that
    much."""
    paper_filter_after(prob, N, PROFILE_WARMUP)
    return paper_filter_after(prob, N, PROFILE_SKIP)


def profile_step(prob: dict, N: int, repeats: int) -> dict:
    """Milliseconds of a paper-scheme step at N, from ``repeats`` real steps in a warm loop: the
    Kalman bank, the new matrices of the moved particles (A(θ), ZOH, H(θ): the ``system`` call),
    and the rest (weights, resampling, Liu–West move, moments) = whole step − the two; medians
    over the steps, so one slow step (a page fault, another process) does not move them."""
    filt = profiled_paper_filter(prob, N)
    spent = {"kalman_bank_ms": 0.0, "zoh_all_particles_ms": 0.0}

    def timed(function, key):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            out = function(*args, **kwargs)
            spent[key] += time.perf_counter() - t0
            return out
        return wrapper

    filt.bank_step = timed(filt.bank_step, "kalman_bank_ms")
    filt.system = timed(filt.system, "zoh_all_particles_ms")
    per_step = []
    for k in range(repeats):
        spent.update(dict.fromkeys(spent, 0.0))
        t0 = time.perf_counter()
        filt.step(prob["y"][PROFILE_SKIP + k], prob["u"][PROFILE_SKIP + k])
        total = time.perf_counter() - t0
        per_step.append((spent["kalman_bank_ms"], spent["zoh_all_particles_ms"],
                         total - spent["kalman_bank_ms"] - spent["zoh_all_particles_ms"]))
    medians = np.median(np.array(per_step), axis=0) * 1e3
    return dict(zip(("kalman_bank_ms", "zoh_all_particles_ms", "rest_of_paper_scheme_step_ms"),
                    (float(v) for v in medians)))


def bank_call_cost(prob: dict, N: int, repeats: int, steps: int = 32) -> dict:
    """Milliseconds of the Kalman bank at N on the particles of :func:`profiled_paper_filter`
    (as :func:`profile_step`): a one-step call, a step inside a ``steps``-step call, and
    the fixed cost of a call, the median over ``repeats`` interleaved pairs of one-step call −
    step of the long call (the gather of every filter's x, P, F and H into the kernel's blocks,
    the scatter of x, P back, the output arrays and the start of the parallel loop)."""
    filt = profiled_paper_filter(prob, N)
    x, P = (filt.x, filt.P) if filt.ancestors is None else \
        (filt.x[filt.ancestors], filt.P[filt.ancestors])
    Y, U = (prob[key][PROFILE_SKIP:PROFILE_SKIP + steps] for key in ("y", "u"))

    def call(k):
        t0 = time.perf_counter()
        kalman_run(x, P, filt.sys, Y[:k], U[:k])
        return (time.perf_counter() - t0) * 1e3 / k
    t = interleaved({"one": lambda: call(1), "many": lambda: call(steps)}, repeats)
    fixed = np.array(t["one"]) - np.array(t["many"])
    return dict(one_step_call_ms=float(np.median(t["one"])),
                per_step_in_long_call_ms=float(np.median(t["many"])),
                fixed_cost_per_call_ms=float(np.median(fixed)), steps_of_long_call=steps)


def gain_settling(prob: dict, steps: int = 3000) -> dict:
    """How fast one particle's Kalman gain settles (nominal θ, the benchmark's P0 = 1e-10 I):
    the relative change ‖K_k − K_{k−1}‖/‖K_k‖ after FIRST_STEPS and ``steps`` steps, and the
    largest |λ| of the closed loop (I − K H) F below 1 − 1e-6 (the unit modes are the integrators
    d_j − y_wj the measurements do not see)."""
    s = prob["systems"]["numpy"](prob["theta"][None])
    F, H, Q, R = s.F[0], s.H[0], s.Q, s.R
    P, K_old, change = 1e-10 * np.eye(lateral_16state.N_STATES), None, {}
    for k in range(1, steps + 1):
        P = F @ P @ F.T + Q
        K = np.linalg.solve(H @ P @ H.T + R, H @ P).T
        I_KH = np.eye(lateral_16state.N_STATES) - K @ H
        P = I_KH @ P @ I_KH.T + K @ R @ K.T
        if k in (FIRST_STEPS, steps):
            change[k] = float(np.linalg.norm(K - K_old) / np.linalg.norm(K))
        K_old = K
    lam = np.abs(np.linalg.eigvals(I_KH @ F))
    return dict(gain_change_after_first=change[FIRST_STEPS], gain_change_after=change[steps],
                steps=steps, slowest_observable_abs_eig=float(lam[lam < 1 - 1e-6].max()))


def _peak_rss_mb(N: int, n_steps: int) -> float:
    """Peak resident memory (MB) of a fresh process while it runs the paper-scheme RBPF at N.

    The peak is reset (``/proc/self/clear_refs``) after the record is simulated, so it is the
    filter's peak (plus the interpreter and libraries), not the simulation's.
    """
    code = ("from railpaper.bench.rbpf_engine import lateral_problem, time_filter\n"
            "prob = lateral_problem(400)\n"
            "open('/proc/self/clear_refs', 'w').write('5')\n"
            f"time_filter(prob, 'rbpf-paper', {N}, {n_steps})\n"
            "status = open('/proc/self/status').read().split('VmHWM:')[1]\n"
            "print(int(status.split()[0]) / 1024)\n")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    # ``python -c`` puts its working directory (the checkout) first on the child's path
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=root)
    return float(out.stdout.split()[-1])


def peak_memory_mb(N: int, n_steps: int) -> dict:
    """Peak RSS at N and at N = 10 (same script); their difference is what N particles cost."""
    big, small = _peak_rss_mb(N, n_steps), _peak_rss_mb(10, n_steps)
    n = lateral_16state.N_STATES
    per_particle = (3 * n * n + 2 * n * 5 + 2 * n + 2 * 5 + 5) * 8     # x, P, F, H, G, θ (bytes)
    return dict(peak_rss_mb=big, peak_rss_N10_mb=small, particles_mb=big - small,
                bank_arrays_mb=N * per_particle / 2 ** 20)


def _row(kind: str, engine: str, N: int, steps: int, seconds: list[float], **extra) -> dict:
    s = summary(rates(seconds))
    return dict(problem="lateral-16", filter=kind, engine=engine, N=N, steps=steps,
                steps_per_s=s["median"], steps_per_s_min=s["min"], steps_per_s_max=s["max"],
                repeats=len(seconds), us_per_particle_step=1e6 / s["median"] / N, **extra)


def main_payload(quick: bool, progress=print, repeats: int | None = None, smoke: bool = False
                 ) -> dict:
    """Run the whole benchmark; returns the JSON payload (see railpaper.bench.report).

    ``smoke``: the same payload from the least work that fills every key (2 alternations,
    N = 100 and 1000 besides the memory probe, a few steps each) — for the test suite's book,
    whose page structure is tested, not its numbers; it implies ``quick``."""
    loads = LoadLog()
    if smoke:
        quick, repeats = True, 2
    repeats = repeats or (QUICK_REPEATS if quick else REPEATS)
    sizes = (dict(working=40, paper=10, fp_working=6, fp_paper=2) if smoke else
             dict(working=200 if quick else 1000, paper=40 if quick else 200,
                  fp_working=30 if quick else 150, fp_paper=20 if quick else 25))
    steady = dict(skip=1000 if quick else 2000, steps=50 if smoke else 200 if quick else 1000)
    prob = lateral_problem(max(sizes["working"], steady["skip"] + steady["steps"]) + 10)
    progress("railpaper bench: compiling kernels")
    time_filter(prob, "rbpf-paper", 70, 3)
    time_filter(prob, "qgrbpf", 70, 3)
    loads.sample("start")
    rows, spread, ratios = [], {}, {}
    Ns = (100, 1000) if smoke else (100, 1000, 10000) if quick else (100, 300, 1000, 3000, 10000)
    for N in Ns:
        scale = max(1, N // 1000)
        steps = {k: max(5, sizes[k] // scale) for k in ("working", "paper")}
        runs = {"rbpf-working": lambda: time_filter(prob, "rbpf-working", N, steps["working"])[0],
                "rbpf-paper": lambda: time_filter(prob, "rbpf-paper", N, steps["paper"])[0],
                "qgrbpf": lambda: time_filter(prob, "qgrbpf", N, steps["paper"])[0]}
        if N == 1000:
            runs["step()"] = lambda: time_filter(prob, "rbpf-working", N, sizes["working"],
                                                 per_step=True)[0]
        progress(f"railpaper bench: N={N}, {' / '.join(runs)} interleaved x {repeats}")
        t = interleaved(runs, repeats)
        loads.sample(f"N={N}")
        for kind in ("rbpf-working", "rbpf-paper", "qgrbpf"):
            rows.append(_row(kind, "compiled", N, steps["paper" if kind != "rbpf-working"
                                                          else "working"], t[kind]))
        r = paired_ratio(t["qgrbpf"], t["rbpf-paper"])
        ratios[f"time_ratio_qgrbpf_over_rbpf_N{N}"] = r["median"]
        spread[f"time_ratio_qgrbpf_over_rbpf_N{N}"] = [r["min"], r["max"]]
        if N == 1000:
            rows.append(_row("rbpf-working", "compiled, step()", N, sizes["working"],
                             t["step()"]))
    N = 1000
    progress(f"railpaper bench: rbpf-working N={N}, steps 1-{FIRST_STEPS} and settled x {repeats}")
    timeline = interleaved({"run": lambda: working_timeline(prob, N, **steady)}, repeats)["run"]
    loads.sample("timeline")
    first = [t[0] for t in timeline]
    resamplings = sorted({t[2] for t in timeline})
    rows.append(_row("rbpf-working", "compiled, settled", N, steady["steps"],
                     [t[1] for t in timeline]))
    ibis_steps = 20 if smoke else 100 if quick else FIRST_STEPS
    progress(f"railpaper bench: IBIS N={N}, steps 1-{ibis_steps} x {repeats}")
    ibis = interleaved({"ibis": lambda: time_ibis(prob, N, ibis_steps)}, repeats)["ibis"]
    loads.sample("ibis")
    rows.append(_row("ibis", "compiled", N, ibis_steps, [t[0] for t in ibis],
                     resamplings=ibis[0][1], filter_steps_per_step=ibis[0][2] / ibis_steps / N))
    baselines = {}
    for kind, k in (("rbpf-working", "fp_working"), ("rbpf-paper", "fp_paper")):
        steps = sizes[k]
        estimates = {}

        def run(engine, kind=kind, steps=steps, estimates=estimates):
            dt, est = time_filter(prob, kind if engine == "compiled" else f"{kind}:{engine}",
                                  N, steps)
            estimates.setdefault(engine, est)
            return dt
        progress(f"railpaper bench: {kind} N={N} compiled / numpy / filterpy interleaved "
                 f"x {repeats}, {steps} steps")
        t = interleaved({e: (lambda e=e: run(e)) for e in ("compiled", "numpy", "filterpy")},
                        repeats)
        loads.sample(f"baselines {kind}")
        ours = estimates["compiled"]
        for engine in ("numpy", "filterpy"):
            r = paired_ratio(t[engine], t["compiled"])
            diff = float(np.max(np.abs(estimates[engine] - ours) / np.abs(ours)))
            rows.append(_row(kind, engine, N, steps, t[engine], speedup_of_compiled=r["median"],
                             speedup_of_compiled_min=r["min"], speedup_of_compiled_max=r["max"],
                             max_rel_theta_diff=diff))
            baselines[(kind, engine)] = r
    progress("railpaper bench: profile, gain settling and peak memory")
    prof = profile_step(prob, 1000, 2 if smoke else 5 if quick else 20)
    budget = step_budget(prob, prof, 1000)
    call_cost = bank_call_cost(prob, 1000, 3 if smoke else 7 if quick else 15)
    settling = gain_settling(prob)
    mem = peak_memory_mb(10000, 3)
    loads.sample("end")

    def row(kind, engine="compiled", N=1000):
        return next(r for r in rows if r["filter"] == kind and r["engine"] == engine
                    and r["N"] == N)
    first_rates = summary(rates(first))
    headline = dict(
        steps_per_s_rbpf_lateral_N1000=row("rbpf-working"),
        steps_per_s_rbpf_lateral_N1000_paper_scheme=row("rbpf-paper"),
        steps_per_s_rbpf_lateral_N1000_step_api=row("rbpf-working", "compiled, step()"),
        steps_per_s_rbpf_lateral_N1000_settled=row("rbpf-working", "compiled, settled"),
        steps_per_s_qgrbpf_lateral_N1000=row("qgrbpf"),
        steps_per_s_ibis_lateral_N1000_first=row("ibis"))
    for key, r in headline.items():
        headline[key], spread[key] = r["steps_per_s"], [r["steps_per_s_min"], r["steps_per_s_max"]]
    speedups = dict(speedup_vs_filterpy_lateral_N1000=("rbpf-working", "filterpy"),
                    speedup_vs_filterpy_lateral_N1000_paper_scheme=("rbpf-paper", "filterpy"),
                    speedup_vs_numpy_lateral_N1000=("rbpf-working", "numpy"),
                    speedup_vs_numpy_lateral_N1000_paper_scheme=("rbpf-paper", "numpy"))
    for key, which in speedups.items():
        speedups[key] = baselines[which]["median"]
        spread[key] = [baselines[which]["min"], baselines[which]["max"]]
    spread["steps_per_s_rbpf_lateral_N1000_first1000"] = [first_rates["min"], first_rates["max"]]
    settings = prob["settings"]
    return dict(
        **headline, settled_window=steady, **speedups, **ratios,
        steps_per_s_rbpf_lateral_N1000_first1000=first_rates["median"],
        resamplings_first1000=resamplings[0] if len(resamplings) == 1 else resamplings,
        profile_N1000_ms=prof, bank_call_N1000_ms=call_cost, flops_N1000=budget,
        memory_N10000=mem, quick=quick, smoke=smoke,
        sizes=sizes, repeats=repeats,
        spread=spread, gain_settling=settling,
        setup=dict(states=lateral_16state.N_STATES, channels=len(lateral_16state.CHANNELS),
                   dt_s=settings.dt_s,
                   speed_kmh=settings.speed_kmh, ess_fraction=settings.ess_fraction,
                   tempering_steps=settings.tempering_steps,
                   working_delta=settings.working_delta, paper_delta=settings.paper_delta,
                   max_chunk=MAX_CHUNK, first_steps=FIRST_STEPS,
                   particles=list(Ns), baseline_N=N),
        machine=dict(machine(), **loads.as_dict()), rows=rows)


if __name__ == "__main__":
    print(json.dumps(main_payload("--quick" in sys.argv), indent=1))

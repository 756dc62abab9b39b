"""Benchmark of the RBPF engine on paper 003's lateral model (16 states, 5 channels, 1 kHz).

Every number is measured in this process on the same simulated record (the chapter's
``simulate_lateral`` at its default settings), against baselines run here too:

* ``compiled``: the library's RBPF / Q-GRBPF (numba Kalman bank + balanced Taylor ZOH);
* ``numpy``: the same filters on the textbook path — stacked ``scipy.linalg.expm`` + numpy
  predict / Joseph update (``engine="numpy"``);
* ``filterpy``: :class:`benchmarks.filterpy_rbpf.FilterpyRBPF`, one filterpy filter per particle.

Speed-ups compare the same steps of the same record with the same seed; the estimates of the
baselines are compared with ours (``max_rel_theta_diff``).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time

import numpy as np

from railpaper.discretise import zoh
from railpaper.linear_gaussian import LinearGaussianBatch
from railpaper.estimators.qgrbpf import QuasiGaussianRBPF
from railpaper.estimators.rbpf import RaoBlackwellisedPF
from railpaper.experiments import rbpf_parameter_estimation as E
from railpaper.models import lateral_16state as L

from benchmarks.filterpy_rbpf import FilterpyRBPF


def lateral_problem(n_steps: int, seed: int = 0) -> dict:
    """The chapter's default lateral record (n_steps at 1 kHz) and the filter's model."""
    p = dict(E.SPEC.resolve({"n_steps": max(n_steps, 400)}, False))
    fixed, theta = E.vehicle()
    data = E.simulate_lateral(p, fixed, theta, seed)
    Q, R = E.filter_noise(fixed, theta, p, data["du_var"])
    v = p["speed_kmh"] / 3.6
    A0, Ak = L.affine_terms(fixed, v)
    fast = L.lateral_system(fixed, v, p["dt_s"], Q, R)

    def textbook(th):                          # stacked scipy expm: the straightforward path
        A = L.a_of_theta(A0, Ak, th)
        F, G = zoh(A, L.input_matrix(), p["dt_s"])
        return LinearGaussianBatch(F, Q, L.measurement_matrix(A), R, G)

    return dict(p=p, theta=theta, y=data["y"], u=data["u"], Q=Q, R=R, A0=A0, Ak=Ak,
                systems={"compiled": fast, "numpy": textbook})


def scheme_options(p: dict, scheme: str) -> dict:
    if scheme == "paper":
        return dict(scheme="paper", delta=p["paper_delta"])
    return dict(scheme="working", delta=p["working_delta"], ess_fraction=p["ess_fraction"],
                tempering_steps=p["tempering_steps"], log_mask=np.ones(5, bool))


def make_filter(prob: dict, kind: str, N: int, seed: int = 11):
    """kind: 'rbpf-working', 'rbpf-paper', 'qgrbpf' (+ ':numpy' or ':filterpy' for baselines)."""
    name, _, engine = kind.partition(":")
    engine = engine or "compiled"
    rng = np.random.default_rng(seed)
    p, theta = prob["p"], prob["theta"]
    theta0 = theta * rng.uniform(p["prior_low"], p["prior_high"], (N, 5))
    x0, P0 = np.zeros(L.N_STATES), 1e-10 * np.eye(L.N_STATES)
    if name == "qgrbpf":
        return QuasiGaussianRBPF(prob["systems"][engine], theta0, x0, P0, rng, engine=engine)
    opts = scheme_options(p, name.split("-")[1])
    if engine == "filterpy":
        return FilterpyRBPF(prob["A0"], prob["Ak"], L.input_matrix(), L.measurement_matrix,
                            p["dt_s"], prob["Q"], prob["R"], theta0, x0, P0, rng, **opts)
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
        est = np.array([o["theta_mean"] for o in filt.steps(Y, U)])
    else:
        est = np.empty((n_steps, 5))
        for k in range(n_steps):
            out = filt.step(Y[k], U[k])
            est[k] = out if isinstance(out, np.ndarray) else out["theta_mean"]
    return (time.perf_counter() - t0) / n_steps, est


def profile_step(prob: dict, N: int, repeats: int) -> dict:
    """Milliseconds of a paper-scheme step at N, from ``repeats`` real steps in a warm loop: the
    Kalman bank, the new matrices of the moved particles (A(θ), ZOH, H(θ): the ``system`` call),
    and the rest (weights, resampling, Liu–West move, moments) = whole step − the two; medians
    over the steps, so one slow step (a page fault, another process) does not move them."""
    from railpaper.estimators import rbpf as rbpf_module
    filt = make_filter(prob, "rbpf-paper", N)
    for k in range(5):
        filt.step(prob["y"][k], prob["u"][k])
    spent = {"kalman_bank_ms": 0.0, "zoh_all_particles_ms": 0.0}

    def timed(function, key):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            out = function(*args, **kwargs)
            spent[key] += time.perf_counter() - t0
            return out
        return wrapper

    bank = rbpf_module.kalman_step
    rbpf_module.kalman_step = timed(bank, "kalman_bank_ms")      # what bank_step calls
    filt.system = timed(filt.system, "zoh_all_particles_ms")
    per_step = []
    try:
        for k in range(repeats):
            spent.update(dict.fromkeys(spent, 0.0))
            t0 = time.perf_counter()
            filt.step(prob["y"][5 + k], prob["u"][5 + k])
            total = time.perf_counter() - t0
            per_step.append((spent["kalman_bank_ms"], spent["zoh_all_particles_ms"],
                             total - spent["kalman_bank_ms"] - spent["zoh_all_particles_ms"]))
    finally:
        rbpf_module.kalman_step = bank
    medians = np.median(np.array(per_step), axis=0) * 1e3
    return dict(zip(("kalman_bank_ms", "zoh_all_particles_ms", "rest_of_paper_scheme_step_ms"),
                    (float(v) for v in medians)))


def _peak_rss_mb(N: int, n_steps: int) -> float:
    """Peak resident memory (MB) of a fresh process while it runs the paper-scheme RBPF at N.

    The peak is reset (``/proc/self/clear_refs``) after the record is simulated, so it is the
    filter's peak (plus the interpreter and libraries), not the simulation's.
    """
    code = ("from benchmarks.rbpf_engine import lateral_problem, time_filter\n"
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
    n = L.N_STATES
    per_particle = (3 * n * n + 2 * n * 5 + 2 * n + 2 * 5 + 5) * 8     # x, P, F, H, G, θ (bytes)
    return dict(peak_rss_mb=big, peak_rss_N10_mb=small, particles_mb=big - small,
                bank_arrays_mb=N * per_particle / 2 ** 20)


def machine() -> dict:
    import numba
    cfg = np.show_config(mode="dicts")
    blas = cfg.get("Build Dependencies", {}).get("blas", {})
    cpu = platform.processor()
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")),
                       cpu)
    return dict(cores=os.cpu_count(), cpu=cpu, python=platform.python_version(),
                numpy=np.__version__, blas=f"{blas.get('name', '?')} {blas.get('version', '')}",
                numba=numba.__version__, numba_threads=numba.get_num_threads())


def main_payload(quick: bool, progress=print) -> dict:
    """Run the whole benchmark; returns the JSON payload (see railpaper.pipeline.bench)."""
    load_before = os.getloadavg()
    sizes = dict(working=200 if quick else 1000, paper=40 if quick else 200,
                 fp_working=30 if quick else 150, fp_paper=6 if quick else 25)
    steady = dict(skip=1000 if quick else 2000, steps=200 if quick else 1000)
    prob = lateral_problem(max(sizes["working"], steady["skip"] + steady["steps"]) + 10)
    progress("railpaper bench: compiling kernels")
    time_filter(prob, "rbpf-paper", 70, 3)
    time_filter(prob, "qgrbpf", 70, 3)
    rows = []
    Ns = (100, 1000, 10000) if quick else (100, 300, 1000, 3000, 10000)
    for N in Ns:
        scale = max(1, N // 1000)
        for kind, k in (("rbpf-working", "working"), ("rbpf-paper", "paper"), ("qgrbpf", "paper")):
            steps = max(5, sizes[k] // scale)
            progress(f"railpaper bench: {kind} N={N}, {steps} steps")
            dt, _ = time_filter(prob, kind, N, steps)
            rows.append(dict(problem="lateral-16", filter=kind, engine="compiled", N=N,
                             steps=steps, steps_per_s=1 / dt, us_per_particle_step=dt / N * 1e6))
    N = 1000
    progress(f"railpaper bench: rbpf-working, one step() per measurement, N={N}")
    dt_step, _ = time_filter(prob, "rbpf-working", N, sizes["working"], per_step=True)
    rows.append(dict(problem="lateral-16", filter="rbpf-working", engine="compiled, step()",
                     N=N, steps=sizes["working"], steps_per_s=1 / dt_step,
                     us_per_particle_step=dt_step / N * 1e6))
    progress(f"railpaper bench: rbpf-working N={N}, steps after {steady['skip']} (settled)")
    dt_steady, _ = time_filter(prob, "rbpf-working", N, steady["steps"], skip=steady["skip"])
    rows.append(dict(problem="lateral-16", filter="rbpf-working", engine="compiled, settled",
                     N=N, steps=steady["steps"], steps_per_s=1 / dt_steady,
                     us_per_particle_step=dt_steady / N * 1e6))
    baselines = {}
    for kind, k in (("rbpf-working", "fp_working"), ("rbpf-paper", "fp_paper")):
        steps = sizes[k]
        dt_ours, est_ours = time_filter(prob, kind, N, steps)
        for engine in ("numpy", "filterpy"):
            progress(f"railpaper bench: {kind}:{engine} N={N}, {steps} steps")
            dt, est = time_filter(prob, f"{kind}:{engine}", N, steps)
            diff = float(np.max(np.abs(est - est_ours) / np.abs(est_ours)))
            rows.append(dict(problem="lateral-16", filter=kind, engine=engine, N=N, steps=steps,
                             steps_per_s=1 / dt, us_per_particle_step=dt / N * 1e6,
                             speedup_of_compiled=dt / dt_ours, max_rel_theta_diff=diff))
            baselines[(kind, engine)] = dt / dt_ours
    progress("railpaper bench: profile and peak memory")
    prof = profile_step(prob, 1000, 5 if quick else 20)
    mem = peak_memory_mb(10000, 3)

    def rate(kind, N):
        return next(r["steps_per_s"] for r in rows
                    if r["filter"] == kind and r["engine"] == "compiled" and r["N"] == N)
    ratios = {f"time_ratio_qgrbpf_over_rbpf_N{N}": rate("rbpf-paper", N) / rate("qgrbpf", N)
              for N in Ns}
    return dict(
        steps_per_s_rbpf_lateral_N1000=rate("rbpf-working", 1000),
        steps_per_s_rbpf_lateral_N1000_paper_scheme=rate("rbpf-paper", 1000),
        steps_per_s_rbpf_lateral_N1000_step_api=1 / dt_step,
        steps_per_s_rbpf_lateral_N1000_settled=1 / dt_steady, settled_window=steady,
        steps_per_s_qgrbpf_lateral_N1000=rate("qgrbpf", 1000),
        speedup_vs_filterpy_lateral_N1000=baselines[("rbpf-working", "filterpy")],
        speedup_vs_filterpy_lateral_N1000_paper_scheme=baselines[("rbpf-paper", "filterpy")],
        speedup_vs_numpy_lateral_N1000=baselines[("rbpf-working", "numpy")],
        speedup_vs_numpy_lateral_N1000_paper_scheme=baselines[("rbpf-paper", "numpy")],
        **ratios, profile_N1000_ms=prof, memory_N10000=mem, quick=quick, sizes=sizes,
        machine=dict(machine(), load_before=list(load_before), load_after=list(os.getloadavg())),
        rows=rows)


if __name__ == "__main__":
    print(json.dumps(main_payload("--quick" in sys.argv), indent=1))

"""``railpaper bench``: run :mod:`railpaper.bench.rbpf_engine`, print its table, write JSON and a plot.

Benchmarks are measurements, not tests: nothing here asserts a speed.  Every text made here (the
terminal table, the book's Performance page) is built from the bench payload alone, and no ratio
between engines is printed from a run in which other work competed for the cores
(:func:`railpaper.bench.verdict.ratio_verdict`): the reason is printed instead.  The
goal table and FLOP sentence are :mod:`railpaper.bench.goals`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from railpaper.bench import rbpf_engine as engine
from railpaper.bench.goals import flops_line, goal_cells, goal_rows, goals_markdown
from railpaper.bench.verdict import WITHHELD, is_ratio, other_work, ratio_verdict


class BenchError(ValueError):
    """Bad input to the bench (one line; the CLI exits 2 on it as on every ValueError)."""


REAL_TIME_STEPS_PER_S = 1000.0          # paper 003's lateral model is sampled at 1 kHz


def _rate(r: dict) -> str:
    spread = (f" ({r['steps_per_s_min']:.1f}-{r['steps_per_s_max']:.1f})"
              if "steps_per_s_min" in r else "")
    return f"{r['steps_per_s']:.1f}{spread}"


def _speedup(r: dict, ok: bool) -> str:
    if "speedup_of_compiled" not in r:
        return ""
    if not ok:
        return WITHHELD
    spread = (f" ({r['speedup_of_compiled_min']:.1f}-{r['speedup_of_compiled_max']:.1f})"
              if "speedup_of_compiled_min" in r else "")
    return f"{r['speedup_of_compiled']:.1f}{spread}"


def format_table(payload: dict) -> str:
    """The benchmark table (plain text, aligned) and the headline numbers."""
    ok, reason = ratio_verdict(payload["machine"])
    head = ("problem", "filter", "engine", "N", "steps", "steps/s (min-max)", "us/particle-step",
            "compiled is x faster (min-max)", "max rel theta diff")
    rows = [head]
    for r in payload["rows"]:
        rows.append((r["problem"], r["filter"], r["engine"], str(r["N"]), str(r["steps"]),
                     _rate(r), f"{r['us_per_particle_step']:.2f}", _speedup(r, ok),
                     f"{r['max_rel_theta_diff']:.1e}" if "max_rel_theta_diff" in r else ""))
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines += ["", f"medians over {payload.get('repeats', 1)} interleaved alternations; {reason}"]
    spread = payload.get("spread", {})
    for key, value in payload.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool) and key != "repeats":
            if is_ratio(key) and not ok:
                lines.append(f"{key} = {WITHHELD}")
                continue
            rng = f" (min-max {spread[key][0]:.4g}-{spread[key][1]:.4g})" if key in spread else ""
            lines.append(f"{key} = {value:.4g}{rng}")
    prof = payload["profile_N1000_ms"]
    lines.append("where a paper-scheme step goes at N = 1000 (ms): "
                 + ", ".join(f"{k} {v:.2f}" for k, v in prof.items()))
    if flops_line(payload):
        lines.append(flops_line(payload))
    goals = [("goal at N = 1000", "target", "measured (min-max)", "", "factor missing")]
    goals += [(g["goal"],) + goal_cells(g) for g in goal_rows(payload)]
    gw = [max(len(row[i]) for row in goals) for i in range(5)]
    lines += [""] + ["  ".join(c.ljust(w) for c, w in zip(row, gw)).rstrip() for row in goals]
    mem = payload["memory_N10000"]
    lines.append(f"memory at N = 10000: peak RSS {mem['peak_rss_mb']:.0f} MB, "
                 f"{mem['particles_mb']:.0f} MB more than at N = 10 (one copy of the particle "
                 f"bank x, P, F, H, G: {mem['bank_arrays_mb']:.0f} MB)")
    m = payload["machine"]
    lines.append(f"machine: {m['cores']} cores, {m['cpu']}, Python {m['python']}, numpy "
                 f"{m['numpy']} ({m['blas']}), numba {m['numba']} ({m['numba_threads']} threads)")
    return "\n".join(lines)


def _real_time(payload: dict) -> float:
    """Steps per second of real time: the model's sample rate."""
    return 1.0 / payload["setup"]["dt_s"] if "setup" in payload else REAL_TIME_STEPS_PER_S


def plot_steps_per_s(payload: dict, path: Path) -> Path:
    """Steps per second against N (log-log, min-max bars), with the real-time line."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.2))
    styles = {"rbpf-working": "o-", "rbpf-paper": "s-", "qgrbpf": "^-"}
    for kind, style in styles.items():
        pts = sorted((r["N"], r["steps_per_s"], r.get("steps_per_s_min", r["steps_per_s"]),
                      r.get("steps_per_s_max", r["steps_per_s"])) for r in payload["rows"]
                     if r["filter"] == kind and r["engine"] == "compiled")
        N, rate, low, high = (list(c) for c in zip(*pts))
        ax.errorbar(N, rate, yerr=[[a - b for a, b in zip(rate, low)],
                                   [b - a for a, b in zip(rate, high)]],
                    fmt=style, capsize=3, label=f"{kind} (compiled)")
    for r in payload["rows"]:
        if r["filter"] == "ibis":
            ax.plot(r["N"], r["steps_per_s"], "D", ms=7, color="tab:purple",
                    label=f"IBIS, steps 1-{r['steps']} (compiled)")
        elif r["engine"] != "compiled":
            marker = "x" if r["engine"] == "filterpy" else "+"
            ax.plot(r["N"], r["steps_per_s"], marker, ms=9, color="0.3")
            ax.annotate(f"{r['filter']}:{r['engine']}", (r["N"], r["steps_per_s"]),
                        textcoords="offset points", fontsize=7, color="0.3",
                        xytext=(6, -10) if r["engine"] == "filterpy" else (6, 3))
    rt = _real_time(payload)
    ax.axhline(rt, color="tab:red", lw=1, ls="--")
    ax.text(110, rt * 1.15, f"real time at {rt:g} samples/s", color="tab:red", fontsize=8)
    ax.set(xscale="log", yscale="log", xlabel="particles N", ylabel="filter steps per second",
           title="Paper 003 lateral model: RBPF engine speed (median, min-max)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def run_bench(quick: bool = False, out: str | Path | None = None) -> dict:
    """Run the benchmark, print the table; write ``out`` (JSON) and ``out``'s plot if given."""
    if out is not None and Path(out).suffix != ".json":
        raise BenchError(f"--out must name a .json file, got {out}")
    payload = engine.main_payload(quick, progress=lambda m: print(m, file=sys.stderr))
    print(format_table(payload))
    if out is not None:
        out = Path(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n")
        tmp.replace(out)
        plot_steps_per_s(payload, out.with_suffix(".png"))
    return payload


#: Readable names of the profile's parts (the JSON keeps the keys).
PROFILE_LABELS = {"kalman_bank_ms": "Kalman bank",
                  "zoh_all_particles_ms": "new matrices of the moved particles (A(θ), ZOH, H(θ))",
                  "rest_of_paper_scheme_step_ms": "the rest (weights, resampling, move, moments)"}


def setup_markdown(payload: dict) -> str:
    """The page's 'what is measured' numbers: problem, schemes, sizes, repeats (from the run)."""
    s, z = payload["setup"], payload["sizes"]
    return "\n".join([
        f"- **Problem**: {s['states']} states, {s['channels']} measurement channels, sampled "
        f"every {s['dt_s'] * 1e3:g} ms ({_real_time(payload):g} steps/s is real time), "
        f"{s['speed_kmh']:g} km/h.",
        f"- **Working scheme**: resample when ESS < {s['ess_fraction']:g} N, move only after "
        f"resampling (Liu–West δ = {s['working_delta']:g}), likelihood tempering over the first "
        f"{s['tempering_steps']} steps; the Kalman bank runs over chunks of up to "
        f"{s['max_chunk']} steps, so an estimate can be up to {s['max_chunk']} samples late.",
        f"- **Paper scheme**: resampling and a Liu–West move (δ = {s['paper_delta']:g}) of every "
        "particle at every step.",
        f"- **Sizes**: N = {', '.join(str(n) for n in s['particles'])}; steps timed per filter "
        f"at N = 1000: working {z['working']}, paper and Q-GRBPF {z['paper']} (fewer at larger "
        f"N); baselines at N = {s['baseline_N']}: working {z['fp_working']}, paper "
        f"{z['fp_paper']} steps; the start-up rate over steps 1–{s['first_steps']}; "
        f"{size_name(payload)} sizes.",
        f"- **Repeats**: every compared set of filters is timed interleaved (A B C A B C …), "
        f"{payload['repeats']} alternations, a fresh filter with the same seed each time; rates "
        "are medians with the min–max over the alternations, ratios the median of the "
        "per-alternation ratios with theirs.",
    ]) + "\n"


def format_markdown(payload: dict) -> str:
    """The benchmark as MyST markdown: the table, the headline ratios, profile, memory, machine."""
    ok, reason = ratio_verdict(payload["machine"])
    lines = ["| filter | engine | N | steps timed | steps/s (min–max) | µs per particle-step |",
             "|---|---|---|---|---|---|"]
    for r in payload["rows"]:
        lines.append(f"| {r['filter']} | {r['engine']} | {r['N']} | {r['steps']} | "
                     f"{_rate(r).replace('-', '–')} | {r['us_per_particle_step']:.2f} |")
    lines += ["", "The baselines against the compiled engine, on the same steps:", "",
              "| filter | baseline | N | compiled is × faster (min–max) "
              "| max rel. θ difference |", "|---|---|---|---|---|"]
    for r in payload["rows"]:
        if "max_rel_theta_diff" in r:
            lines.append(f"| {r['filter']} | {r['engine']} | {r['N']} | "
                         f"{_speedup(r, ok).replace('-', '–')} | "
                         f"{r['max_rel_theta_diff']:.1e} |")
    spread = payload.get("spread", {})
    ratios = ", ".join(
        f"N = {k.rsplit('_N', 1)[1]}: {v:.2f}"
        + (f" ({spread[k][0]:.2f}–{spread[k][1]:.2f})" if k in spread else "")
        for k, v in payload.items() if k.startswith("time_ratio_qgrbpf_over_rbpf_N"))
    prof = payload["profile_N1000_ms"]
    mem, m = payload["memory_N10000"], payload["machine"]
    lines += ["", (f"- Q-GRBPF / RBPF (paper scheme) time per step: {ratios} (paper 004: 0.44)."
                   if ok else f"- Q-GRBPF / RBPF (paper scheme) time per step: {reason}."),
              "- One paper-scheme step at N = 1000 (ms, median of real steps in a warm loop): "
              + ", ".join(f"{label} {prof[k]:.2f}" for k, label in PROFILE_LABELS.items()) + ".",
              f"- Memory at N = 10 000: peak RSS {mem['peak_rss_mb']:.0f} MB, "
              f"{mem['particles_mb']:.0f} MB more than at N = 10; one copy of the particle bank "
              f"is {mem['bank_arrays_mb']:.0f} MB (O(N n²)).",
              f"- Machine: {m['cores']} cores ({m['cpu']}), Python {m['python']}, numpy "
              f"{m['numpy']} with {m['blas']}, numba {m['numba']} on {m['numba_threads']} threads; "
              f"{size_name(payload)} sizes {payload['sizes']}."]
    return "\n".join(lines) + "\n"


def size_name(payload: dict) -> str:
    """'smoke', 'quick' or 'full': which sizes a payload was measured at."""
    return "smoke" if payload.get("smoke") else "quick" if payload["quick"] else "full"


def busy_note(machine: dict) -> str:
    """The load of the run in one paragraph: quiet, busy (ratios withheld) or not recorded."""
    loads = [machine[k][0] for k in ("load_before", "load_after") if k in machine]
    if not loads:
        return "The machine's load was not recorded by this run; ratios are withheld."
    other = other_work(machine)
    other_note = ("" if other is None else
                  f"; work other than the bench at most {max(other, 0):.2f} cores")
    text = (f"Load average (1 min) {loads[0]:.1f} before and {loads[-1]:.1f} after the run"
            + (f", at most {machine['load_max_1min']:.1f} during it"
               if "load_max_1min" in machine else "") + f", on {machine['cores']} cores"
            + other_note)
    if not ratio_verdict(machine)[0]:
        return (f"**The machine was busy**: {text}. Other work competed for the cores, so these "
                "rates are low and no ratio between engines is printed; re-run `railpaper bench` "
                "on a quiet machine before quoting any number.")
    return text + ": the machine was quiet."


def _call_cost_lines(g: dict) -> list[str]:
    """The bank's fixed cost per call, when the run measured it."""
    c = g.get("bank_call_N1000_ms")
    if c is None:
        return []
    return [f"- **A call of the Kalman bank** at N = 1000 costs {c['fixed_cost_per_call_ms']:.2f} "
            f"ms besides its steps ({c['fixed_cost_per_call_ms'] / c['one_step_call_ms']:.0%} "
            f"of a one-step call, {c['one_step_call_ms']:.2f} ms; one step inside a "
            f"{c['steps_of_long_call']}-step call takes {c['per_step_in_long_call_ms']:.2f} ms): "
            "mostly gathering every filter's x, P, F and H from the library's particle-first "
            "arrays into the kernel's blocks and scattering x, P back. The paper scheme pays it "
            "at every step; the Q-GRBPF makes two calls a step, but its prediction stays in the "
            "kernel's blocks for its update, which gathers only H; the working scheme pays it "
            "once per call of several steps."]


def findings_markdown(payload: dict) -> str:
    """The page's 'what stands between this and real time', every number from this run."""
    g = payload
    ok, reason = ratio_verdict(g["machine"])
    prof = g["profile_N1000_ms"]
    step_ms = sum(prof.values())
    rt = _real_time(g)
    first = g.get("steps_per_s_rbpf_lateral_N1000_first1000")
    lines = [
        f"- **Working scheme, first {g['sizes']['working']} steps at N = 1000**: "
        f"{g['steps_per_s_rbpf_lateral_N1000']:.0f} steps/s "
        f"({g['steps_per_s_rbpf_lateral_N1000'] / rt:.2f} × real time); each resampling "
        "moves every particle's θ and so pays one discretisation of the whole stack."]
    if first is not None:
        n_first = g.get("setup", {}).get("first_steps", 1000)
        lines.append(f"- **Steps 1–{n_first} at N = 1000** (the start-up, working scheme): "
                     f"{first:.0f} steps/s ({first / rt:.2f} × real time), with "
                     f"{g['resamplings_first1000']} resamplings in those steps.")
    lines += [
        f"- **Settled working scheme** (steps after {g['settled_window']['skip']}): "
        f"{g['steps_per_s_rbpf_lateral_N1000_settled']:.0f} steps/s "
        f"({g['steps_per_s_rbpf_lateral_N1000_settled'] / rt:.2f} × real time).",
        f"- **Paper scheme** (every particle moved every step): "
        f"{g['steps_per_s_rbpf_lateral_N1000_paper_scheme']:.0f} steps/s; **Q-GRBPF** "
        f"{g['steps_per_s_qgrbpf_lateral_N1000']:.0f} steps/s (its step needs a second "
        "measurement update because the lateral model's H depends on θ).",
        f"- **One paper-scheme step** at N = 1000 takes {step_ms:.1f} ms: "
        + ", ".join(f"{label} {prof[k]:.2f} ms ({prof[k] / step_ms:.0%})"
                    for k, label in PROFILE_LABELS.items()) + ".",
        *_call_cost_lines(g),
        (f"- **Against filterpy** (one filter object per particle): "
         f"{g['speedup_vs_filterpy_lateral_N1000']:.1f}× (working scheme) and "
         f"{g['speedup_vs_filterpy_lateral_N1000_paper_scheme']:.1f}× (paper scheme) faster; "
         f"against our own NumPy path {g['speedup_vs_numpy_lateral_N1000']:.1f}× and "
         f"{g['speedup_vs_numpy_lateral_N1000_paper_scheme']:.1f}×."
         if ok else f"- **Against filterpy and our NumPy path**: {reason}."),
    ]
    if "gain_settling" in g:
        s = g["gain_settling"]
        lines.append(
            f"- **No steady-state shortcut**: one particle's Kalman gain (nominal θ) still "
            f"changes by {s['gain_change_after_first']:.1e} (relative) per step after "
            f"{g.get('setup', {}).get('first_steps', 1000)} steps and by "
            f"{s['gain_change_after']:.1e} after {s['steps']}; the slowest observable mode of "
            f"the filter's closed loop has |λ| = {s['slowest_observable_abs_eig']:.4f} per step.")
    return "\n".join(lines) + "\n"


def write_performance(book_dir: Path, smoke: bool = False) -> Path:
    """Run the quick benchmark for the book's Performance page: ``_generated/`` gets
    ``bench.json``, ``performance_setup.md``, ``performance_table.md``,
    ``performance_findings.md``, ``performance_goals.md`` and ``performance_steps_per_s.png``.
    ``smoke``: the smoke-sized bench (the test suite's book: every key, least work)."""
    out = Path(book_dir) / "_generated"
    out.mkdir(parents=True, exist_ok=True)
    payload = engine.main_payload(True, progress=lambda m: print(m, file=sys.stderr),
                                  smoke=smoke)
    return write_performance_files(payload, out)


def write_performance_files(payload: dict, out: Path) -> Path:
    """The Performance page's generated files from one bench payload (nothing else is read)."""
    (out / "bench.json").write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n")
    (out / "performance_setup.md").write_text(setup_markdown(payload))
    (out / "performance_table.md").write_text(
        busy_note(payload["machine"]) + "\n\n" + format_markdown(payload))
    (out / "performance_findings.md").write_text(findings_markdown(payload))
    (out / "performance_goals.md").write_text(goals_markdown(payload))
    return plot_steps_per_s(payload, out / "performance_steps_per_s.png")

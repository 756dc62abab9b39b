"""``railpaper bench``: run ``benchmarks/rbpf_engine.py``, print its table, write JSON and a plot.

Benchmarks are measurements, not tests: nothing here asserts a speed.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import sys
from pathlib import Path

from railpaper.pipeline.chapters import REPO_DIR, PipelineError

REAL_TIME_STEPS_PER_S = 1000.0          # paper 003's lateral model is sampled at 1 kHz


def _load_benchmarks():
    """``benchmarks.rbpf_engine`` of this checkout, loaded from its file path.

    ``benchmarks/`` is not on ``sys.path`` (and ``sys.path`` is not edited): the package is
    registered in ``sys.modules`` from ``benchmarks/__init__.py`` with its directory as the
    package path, so its modules import each other as ``benchmarks.*``.
    """
    root = REPO_DIR / "benchmarks"
    if not (root / "rbpf_engine.py").exists():
        raise PipelineError(f"benchmarks/ not found in {REPO_DIR} (bench runs from a checkout)")
    loaded = sys.modules.get("benchmarks")
    if loaded is None:
        spec = importlib.util.spec_from_file_location(
            "benchmarks", root / "__init__.py", submodule_search_locations=[str(root)])
        package = importlib.util.module_from_spec(spec)
        sys.modules["benchmarks"] = package
        spec.loader.exec_module(package)
    elif [Path(p).resolve() for p in getattr(loaded, "__path__", [])] != [root.resolve()]:
        raise PipelineError(f"another module named 'benchmarks' is already imported "
                            f"({getattr(loaded, '__file__', loaded)}), not {root}")
    return importlib.import_module("benchmarks.rbpf_engine")


def format_table(payload: dict) -> str:
    """The benchmark table (plain text, aligned) and the headline numbers."""
    head = ("problem", "filter", "engine", "N", "steps", "steps/s", "us/particle-step",
            "compiled is x faster", "max rel theta diff")
    rows = [head]
    for r in payload["rows"]:
        rows.append((r["problem"], r["filter"], r["engine"], str(r["N"]), str(r["steps"]),
                     f"{r['steps_per_s']:.1f}", f"{r['us_per_particle_step']:.2f}",
                     f"{r['speedup_of_compiled']:.1f}" if "speedup_of_compiled" in r else "",
                     f"{r['max_rel_theta_diff']:.1e}" if "max_rel_theta_diff" in r else ""))
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append("")
    for key, value in payload.items():
        if isinstance(value, float):
            lines.append(f"{key} = {value:.4g}")
    prof = payload["profile_N1000_ms"]
    lines.append("where a paper-scheme step goes at N = 1000 (ms): "
                 + ", ".join(f"{k} {v:.2f}" for k, v in prof.items()))
    mem = payload["memory_N10000"]
    lines.append(f"memory at N = 10000: peak RSS {mem['peak_rss_mb']:.0f} MB, "
                 f"{mem['particles_mb']:.0f} MB more than at N = 10 (one copy of the particle "
                 f"bank x, P, F, H, G: {mem['bank_arrays_mb']:.0f} MB)")
    m = payload["machine"]
    lines.append(f"machine: {m['cores']} cores, {m['cpu']}, Python {m['python']}, numpy "
                 f"{m['numpy']} ({m['blas']}), numba {m['numba']} ({m['numba_threads']} threads)")
    return "\n".join(lines)


def plot_steps_per_s(payload: dict, path: Path) -> Path:
    """Steps per second against N (log-log), with the real-time line of a 1 kHz sensor."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.2))
    styles = {"rbpf-working": "o-", "rbpf-paper": "s-", "qgrbpf": "^-"}
    for kind, style in styles.items():
        pts = sorted((r["N"], r["steps_per_s"]) for r in payload["rows"]
                     if r["filter"] == kind and r["engine"] == "compiled")
        ax.plot(*zip(*pts), style, label=f"{kind} (compiled)")
    for r in payload["rows"]:
        if r["engine"] != "compiled":
            marker = "x" if r["engine"] == "filterpy" else "+"
            ax.plot(r["N"], r["steps_per_s"], marker, ms=9, color="0.3")
            ax.annotate(f"{r['filter']}:{r['engine']}", (r["N"], r["steps_per_s"]),
                        textcoords="offset points", fontsize=7, color="0.3",
                        xytext=(6, -10) if r["engine"] == "filterpy" else (6, 3))
    ax.axhline(REAL_TIME_STEPS_PER_S, color="tab:red", lw=1, ls="--")
    ax.text(110, REAL_TIME_STEPS_PER_S * 1.15,
            "real time at 1 kHz", color="tab:red", fontsize=8)
    ax.set(xscale="log", yscale="log", xlabel="particles N", ylabel="filter steps per second",
           title="Paper 003 lateral model (16 states, 5 channels): RBPF engine speed")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def run_bench(quick: bool = False, out: str | Path | None = None) -> dict:
    """Run the benchmark, print the table; write ``out`` (JSON) and ``out``'s plot if given."""
    if out is not None and Path(out).suffix != ".json":
        raise PipelineError(f"--out must name a .json file, got {out}")
    engine = _load_benchmarks()
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


def format_markdown(payload: dict) -> str:
    """The benchmark as MyST markdown: the table, the headline ratios, profile, memory, machine."""
    lines = ["| filter | engine | N | steps timed | steps/s | µs per particle-step "
             "| compiled is × faster | max rel. θ difference |", "|---|---|---|---|---|---|---|---|"]
    for r in payload["rows"]:
        fast = f"{r['speedup_of_compiled']:.1f}" if "speedup_of_compiled" in r else ""
        diff = f"{r['max_rel_theta_diff']:.1e}" if "max_rel_theta_diff" in r else ""
        lines.append(f"| {r['filter']} | {r['engine']} | {r['N']} | {r['steps']} | "
                     f"{r['steps_per_s']:.1f} | {r['us_per_particle_step']:.2f} | {fast} | {diff} |")
    ratios = ", ".join(f"N = {k.rsplit('_N', 1)[1]}: {v:.2f}" for k, v in payload.items()
                       if k.startswith("time_ratio_qgrbpf_over_rbpf_N"))
    prof = payload["profile_N1000_ms"]
    mem, m = payload["memory_N10000"], payload["machine"]
    lines += ["", f"- Q-GRBPF / RBPF (paper scheme) time per step: {ratios} (paper 004: 0.44).",
              "- One paper-scheme step at N = 1000 (ms, real steps in a warm loop): "
              + ", ".join(f"{label} {prof[k]:.2f}" for k, label in PROFILE_LABELS.items()) + ".",
              f"- Memory at N = 10 000: peak RSS {mem['peak_rss_mb']:.0f} MB, "
              f"{mem['particles_mb']:.0f} MB more than at N = 10; one copy of the particle bank "
              f"is {mem['bank_arrays_mb']:.0f} MB (O(N n²)).",
              f"- Machine: {m['cores']} cores ({m['cpu']}), Python {m['python']}, numpy "
              f"{m['numpy']} with {m['blas']}, numba {m['numba']} on {m['numba_threads']} threads; "
              f"{'quick' if payload['quick'] else 'full'} sizes {payload['sizes']}."]
    return "\n".join(lines) + "\n"


def busy_note(machine: dict) -> str:
    """A warning when the 1-minute load average exceeded the core count before or after the run
    (other processes competed for the cores, so the rates are low and ratios unreliable); ''."""
    loads = [machine[k][0] for k in ("load_before", "load_after") if k in machine]
    if not loads:
        return "The machine's load was not recorded by this run."
    text = (f"Load average (1 min) {loads[0]:.1f} before and {loads[-1]:.1f} after the run on "
            f"{machine['cores']} cores")
    if max(loads) > machine["cores"]:
        return (f"**The machine was busy**: {text}. Other work competed for the cores, so these "
                "rates are low and the ratios between engines are unreliable; re-run "
                "`railpaper bench` on a quiet machine before quoting them.")
    return text + ": the machine was quiet."


def findings_markdown(payload: dict) -> str:
    """The page's 'what stands between this and real time', every number from this run."""
    g = payload
    prof = g["profile_N1000_ms"]
    step_ms = sum(prof.values())
    rt = REAL_TIME_STEPS_PER_S
    lines = [
        f"- **Working scheme, first {g['sizes']['working']} steps at N = 1000**: "
        f"{g['steps_per_s_rbpf_lateral_N1000']:.0f} steps/s "
        f"({g['steps_per_s_rbpf_lateral_N1000'] / rt:.2f} × real time at 1 kHz); each resampling "
        "moves every particle's θ and so pays one discretisation of the whole stack.",
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
        f"- **Against filterpy** (one filter object per particle): "
        f"{g['speedup_vs_filterpy_lateral_N1000']:.1f}× (working scheme) and "
        f"{g['speedup_vs_filterpy_lateral_N1000_paper_scheme']:.1f}× (paper scheme) faster; "
        f"against our own NumPy path {g['speedup_vs_numpy_lateral_N1000']:.1f}× and "
        f"{g['speedup_vs_numpy_lateral_N1000_paper_scheme']:.1f}×.",
    ]
    return "\n".join(lines) + "\n"


def write_performance(book_dir: Path) -> Path:
    """Run the quick benchmark for the book's Performance page: ``_generated/`` gets
    ``bench.json``, ``performance_table.md`` and ``performance_steps_per_s.png``."""
    out = Path(book_dir) / "_generated"
    out.mkdir(parents=True, exist_ok=True)
    engine = _load_benchmarks()
    payload = engine.main_payload(True, progress=lambda m: print(m, file=sys.stderr))
    (out / "bench.json").write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n")
    (out / "performance_table.md").write_text(
        busy_note(payload["machine"]) + "\n\n" + format_markdown(payload))
    (out / "performance_findings.md").write_text(findings_markdown(payload))
    return plot_steps_per_s(payload, out / "performance_steps_per_s.png")

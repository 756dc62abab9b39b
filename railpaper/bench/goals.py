"""The engine issue's goals and the FLOP sentence of a bench payload (terminal and page).

Everything here is computed from the payload of one ``railpaper bench`` run; ratios of a run
whose machine was busy are withheld (:func:`railpaper.bench.verdict.ratio_verdict`).
"""

from __future__ import annotations

from railpaper.bench.verdict import WITHHELD, is_ratio, ratio_verdict

#: The engine issue's goals at N = 1000 on the benchmark machine: (label, payload key, sense,
#: target).  ">=": the measured median must reach the target; "<=": must not exceed it.  Real
#: time is 1000 steps/s (the lateral records are sampled at 1 kHz); the IBIS target is three
#: times the 55 steps/s measured when the goal was set (2026-12-03); the bank's share of the
#: dgemm rate is read from the run's FLOP block.
GOALS = (
    ("working scheme (tempered Liu-West), steps 1-1000, real time",
     "steps_per_s_rbpf_lateral_N1000_first1000", ">=", 1000.0),
    ("paper scheme (every particle moved every step), real time",
     "steps_per_s_rbpf_lateral_N1000_paper_scheme", ">=", 1000.0),
    ("Q-GRBPF time / RBPF time (paper scheme)", "time_ratio_qgrbpf_over_rbpf_N1000", "<=", 1.0),
    ("posterior-targeting scheme (IBIS), first steps", "steps_per_s_ibis_lateral_N1000_first",
     ">=", 165.0),
    ("x filterpy-per-particle RBPF, working scheme", "speedup_vs_filterpy_lateral_N1000",
     ">=", 50.0),
    ("x filterpy-per-particle RBPF, paper scheme",
     "speedup_vs_filterpy_lateral_N1000_paper_scheme", ">=", 50.0),
    ("Kalman bank GFLOP/s / dgemm GFLOP/s (same run)", "bank_fraction_of_dgemm", ">=", 0.30),
)


def _value(payload: dict, key: str):
    """A goal's measured value: a top-level payload key, else one of the FLOP block's."""
    if key in payload:
        return payload[key]
    return (payload.get("flops_N1000") or {}).get(key)


def goal_rows(payload: dict) -> list[dict]:
    """Each goal with the run's median, its min-max, met or not and the factor still missing
    (target / measured for "≥" goals, measured / target for "≤"); ratios from a busy run are
    withheld (``measured`` None)."""
    ok, _ = ratio_verdict(payload["machine"])
    spread = payload.get("spread", {})
    out = []
    for label, key, sense, target in GOALS:
        value = _value(payload, key)
        if value is None or (is_ratio(key) and not ok):
            out.append(dict(goal=label, key=key, sense=sense, target=target, measured=None,
                            spread=None, met=None, factor_missing=None,
                            why="not measured in this run" if value is None else WITHHELD))
            continue
        met = value >= target if sense == ">=" else value <= target
        missing = target / value if sense == ">=" else value / target
        out.append(dict(goal=label, key=key, sense=sense, target=target, measured=value,
                        spread=spread.get(key), met=bool(met),
                        factor_missing=None if met else missing))
    return out


def goal_cells(g: dict) -> tuple[str, str, str, str]:
    target = f"{g['sense']} {g['target']:g}"
    if g["measured"] is None:
        return target, g["why"], "", ""
    rng = f" ({g['spread'][0]:.4g}-{g['spread'][1]:.4g})" if g["spread"] else ""
    state = "met" if g["met"] else "missed"
    missing = f"{g['factor_missing']:.1f}x" if g["factor_missing"] else ""
    return target, f"{g['measured']:.4g}{rng}", state, missing


def flops_line(payload: dict) -> str | None:
    """FLOP count of a paper-scheme step and the attained rates, one sentence."""
    f = payload.get("flops_N1000")
    if f is None:
        return None
    nominal = (f", nominal peak {f['nominal_peak_gflops']:.0f} GFLOP/s at {f['clock_ghz']:.2f} "
               f"GHz if {f.get('nominal_flop_per_cycle', 32)} FLOP/cycle/core (an assumption)"
               if f.get("nominal_peak_gflops")
               else "")
    return (f"FLOP of a paper-scheme step at N = {f['N']}: {f['step_gflop'] * 1e3:.1f} MFLOP "
            f"(Kalman bank {f['bank_multiply_adds_per_particle']} and new matrices "
            f"{f['zoh_multiply_adds_per_particle']:.0f} multiply-adds per particle); attained: "
            f"bank {f['bank_gflops']:.1f} GFLOP/s ({f['bank_fraction_of_dgemm']:.0%} of this "
            f"machine's dgemm, {f['dgemm_gflops']:.0f} GFLOP/s), ZOH {f['zoh_gflops']:.1f} "
            f"GFLOP/s ({f['zoh_fraction_of_dgemm']:.0%}){nominal}")


def goals_markdown(payload: dict) -> str:
    """The goals table (target, this run's median and min–max, met or the factor missing) and
    the FLOP sentence, as MyST markdown."""
    lines = ["| goal at N = 1000 | target | measured (min–max) | | factor missing |",
             "|---|---|---|---|---|"]
    for g in goal_rows(payload):
        target, measured, state, missing = goal_cells(g)
        lines.append(f"| {g['goal'].replace('x filterpy', '× filterpy')} | "
                     f"{target.replace('>=', '≥').replace('<=', '≤')} | "
                     f"{measured.replace('-', '–') if g['measured'] is not None else measured} | "
                     f"{state} | {missing.replace('x', '×')} |")
    line = flops_line(payload)
    if line:
        lines += ["", f"- {line}."]
    return "\n".join(lines) + "\n"

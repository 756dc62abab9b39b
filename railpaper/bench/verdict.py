"""May a bench run's ratios between engines be printed?  The machine's load, judged once.

Shared by the terminal table, the JSON findings and the Performance page
(:mod:`railpaper.bench.report`, :mod:`railpaper.bench.goals`).
"""

from __future__ import annotations

WITHHELD = "withheld"


def is_ratio(key: str) -> bool:
    return key.startswith(("speedup_", "time_ratio_"))


#: Most cores other work may take (between two samples of a run) for ratios to be printed.
OTHER_WORK_MAX = 0.5


def other_work(machine: dict) -> float | None:
    """The most cores other work took during the run (``other_max_cores``, or the load-average
    estimate ``other_max_1min`` of the previous version), None where not recorded."""
    key = next((k for k in ("other_max_cores", "other_max_1min") if k in machine), None)
    return None if key is None else machine[key]


def ratio_verdict(machine: dict) -> tuple[bool, str]:
    """May this run's ratios between engines be printed?  (ok, reason in one sentence).

    Not when work other than the bench took more than :data:`OTHER_WORK_MAX` cores between any
    two samples of the run (start, between the interleaved blocks, end): the machine's busy CPU
    time (/proc/stat, steal included) minus the bench's own, per second (``other_max_cores``, see
    ``railpaper.timing.LoadLog``; JSON of the previous version holds a load-average estimate,
    ``other_max_1min``, judged the same way).  A run that recorded only the load (older JSON) is
    judged by the load itself against the core count (the bench's own threads count in it); a
    run that recorded neither, never.  Why not the load alone: on a 2-core machine the bench's
    own two threads make a load of 2.0-2.1 with nothing else running, and the load average still
    holds the tail of work that ended a minute before the bench started (the chapters, in a
    book build).
    """
    other = other_work(machine)
    if other is not None:
        if other > OTHER_WORK_MAX:
            return False, (f"ratios withheld: work other than the bench took {other:.2f} cores "
                           f"between two of its samples (above {OTHER_WORK_MAX:g}), so the "
                           "engines competed with other work for the cores; re-run "
                           "`railpaper bench` on a quiet machine")
        return True, (f"work other than the bench stayed at or below {max(other, 0):.2f} cores "
                      f"(the load average reached {machine.get('load_max_1min', 0):.1f} on "
                      f"{machine['cores']} cores, the bench's own threads included)")
    loads = [machine[k][0] for k in ("load_before", "load_after") if k in machine]
    if "load_max_1min" in machine:
        loads.append(machine["load_max_1min"])
    if not loads:
        return False, "ratios withheld: this run did not record the machine's load"
    top, cores = max(loads), machine["cores"]
    if top > cores:
        return False, (f"ratios withheld: the 1-minute load average reached {top:.1f} on "
                       f"{cores} cores during this run, so the engines competed with other work "
                       "for the cores; re-run `railpaper bench` on a quiet machine")
    return True, f"the 1-minute load average stayed at or below {top:.1f} on {cores} cores"

"""The engine benchmark (``railpaper bench``): paper 003's lateral RBPF on the compiled engine,
the textbook NumPy path and a filterpy-filter-per-particle baseline, timed interleaved in one
process.

:mod:`~railpaper.bench.rbpf_engine` runs the comparisons and returns the payload;
:mod:`~railpaper.bench.filterpy_rbpf` is the baseline; :mod:`~railpaper.bench.flops` counts the
work of a step; :mod:`~railpaper.bench.verdict` decides whether the run was quiet enough to print
ratios; :mod:`~railpaper.bench.goals` is the goal table; :mod:`~railpaper.bench.report` prints,
plots and writes the book's Performance page.  Measurements live in the payloads (``--out``) and
in ``data/bench/``, never in the code.
"""

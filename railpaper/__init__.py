"""railpaper: reproducible rebuild of four papers on railway-vehicle state and parameter estimation.

Layers, lowest first: physics (:mod:`railpaper.contact`, :mod:`railpaper.track`,
:mod:`railpaper.discretise`, :mod:`railpaper.data`, :mod:`railpaper.stats`,
:mod:`railpaper.settling`) -> :mod:`railpaper.engine` (batched linear-Gaussian machinery) ->
:mod:`railpaper.models` (each paper's vehicle) and :mod:`railpaper.estimators` (observers, EKF,
smoother) -> :mod:`railpaper.experiments` (one package per chapter) -> :mod:`railpaper.bench`
-> :mod:`railpaper.pipeline` -> CLI.  Nothing imports upward or in a cycle.
"""

__version__ = "0.1.0"

"""railpaper: reproducible rebuild of four papers on railway-vehicle state and parameter estimation.

Layers, lowest first: physics (:mod:`railpaper.data`, :mod:`railpaper.contact`,
:mod:`railpaper.discretise`, :mod:`railpaper.track`) -> models and estimators ->
experiments -> pipeline -> CLI.  Nothing imports upward.
"""

__version__ = "0.1.0"

"""Chapter ``quasi-gaussian-rbpf`` (paper 004): quasi-Gaussian RBPF versus RBPF on the paper's
toy, with the exact grid posterior as reference.

``SPEC`` (the chapter's parameters), ``Settings`` (its typed settings), ``validate(settings)``
and ``run(settings, progress=None)`` are what the pipeline needs; the modules of the package are
the chapter's parts (``experiment`` is the whole computation, ``figures`` and ``tables`` draw from
its result).
"""

from railpaper.experiments.quasi_gaussian_rbpf.experiment import run, validate
from railpaper.experiments.quasi_gaussian_rbpf.spec import SPEC, Settings

__all__ = ["SPEC", "Settings", "run", "validate"]

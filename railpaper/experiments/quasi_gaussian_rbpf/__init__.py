"""Chapter ``quasi-gaussian-rbpf`` (paper 004): quasi-Gaussian RBPF versus RBPF on the paper's
toy, with the exact grid posterior as reference.

``SPEC`` (the chapter's parameters), ``Settings`` (its typed settings), ``validate(settings)``,
``run(settings, progress=None, record_map=...)`` and ``STUDIES`` (its per-record studies, which
the evidence store and the decisive run compute) are what the pipeline needs; the modules of the package are
the chapter's parts (``experiment`` is the whole computation, ``figures`` and ``tables`` draw from
its result).
"""

from railpaper.experiments.quasi_gaussian_rbpf.experiment import (
    MONTE_CARLO,
    READINGS,
    run,
    validate,
)
from railpaper.experiments.quasi_gaussian_rbpf.spec import SPEC, Settings

#: The chapter's per-record studies.
STUDIES = (MONTE_CARLO, READINGS)


__all__ = ["SPEC", "STUDIES", "Settings", "run", "validate"]

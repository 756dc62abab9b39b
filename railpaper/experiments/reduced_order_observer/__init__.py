"""Chapter ``reduced-order-observer`` (paper 001, Li, Zheng & Chai 2014): single wheelset,
reduced-order observer of the wheelset's vertical states, wheel–rail force by linearised Hertz
contact.

``SPEC`` (the chapter's parameters), ``Settings`` (their typed, frozen values),
``validate(settings)`` and ``run(settings, *, progress=None, record_map=map_in_process)`` are
what the pipeline needs; the modules of the package are the chapter's parts (``experiment`` is
the whole computation, ``evidence`` and ``kalman`` hold its per-seed record studies and their
reduce, ``figures`` and ``tables`` draw from its result).
"""

from railpaper.experiments.reduced_order_observer.evidence import HERTZ, MONTE_CARLO
from railpaper.experiments.reduced_order_observer.experiment import run, validate
from railpaper.experiments.reduced_order_observer.kalman import (
    ESTIMATOR_RECORDS,
    TRACK_NOISE_RECORDS,
)
from railpaper.experiments.reduced_order_observer.spec import SPEC, Settings

#: The chapter's per-record studies (the evidence store and the decisive run compute them).
STUDIES = (MONTE_CARLO, HERTZ, ESTIMATOR_RECORDS, TRACK_NOISE_RECORDS)

__all__ = ["SPEC", "STUDIES", "Settings", "run", "validate"]

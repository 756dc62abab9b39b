"""Chapter ``reduced-order-observer`` (paper 001, Li, Zheng & Chai 2014): single wheelset,
reduced-order observer of the wheelset's vertical states, wheel–rail force by linearised Hertz
contact.

``SPEC`` (the chapter's parameters), ``Settings`` (their typed, frozen values),
``validate(settings)`` and ``run(settings, *, progress=None, record_map=map_in_process)`` are
what the pipeline needs; the modules of the package are the chapter's parts (``experiment`` is
the whole computation, ``evidence`` and ``kalman`` hold its per-seed record studies and their
reduce, ``figures`` and ``tables`` draw from its result).
"""

from railpaper.experiments.reduced_order_observer.experiment import STUDIES, run, validate
from railpaper.experiments.reduced_order_observer.spec import SPEC, Settings

__all__ = ["SPEC", "STUDIES", "Settings", "run", "validate"]

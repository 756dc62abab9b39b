"""Chapter ``reduced-order-observer`` (paper 001, Li, Zheng & Chai 2014): single wheelset,
reduced-order observer of the wheelset's vertical states, wheel–rail force by linearised Hertz
contact.

``SPEC`` (the chapter's parameters), ``validate(params)`` and ``run(quick=False, progress=None,
**params)`` are what the pipeline needs; the modules of the package are the chapter's parts
(``experiment`` is the whole computation, ``figures`` and ``tables`` draw from its result).
"""

from railpaper.experiments.reduced_order_observer.experiment import run, validate
from railpaper.experiments.reduced_order_observer.spec import SPEC

__all__ = ["SPEC", "run", "validate"]

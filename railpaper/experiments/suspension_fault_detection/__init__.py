"""Appendix ``suspension-fault-detection`` (no paper: our study on paper 003's lateral vehicle):
how soon a failed anti-yaw damper or a softened secondary spring shows in the data, by two
residual tests (cusum, chi2), two detectors that do not know the fault (glr, bayes) and an
oracle that does, at thresholds for hours between false alarms, on a ladder of sensors.

``SPEC``, its ``Settings``, ``validate(settings)`` and ``run(settings, progress=None)`` are what
the pipeline needs, with ``STUDIES`` (the stored fault-free running) and ``stored_sizes(settings)``
(its size); the package's modules are the appendix's parts (``experiment`` is the whole
computation, ``figures`` and ``tables`` draw from its result).
"""

from railpaper.experiments.suspension_fault_detection.experiment import (
    STUDIES,
    run,
    stored_sizes,
    validate,
)
from railpaper.experiments.suspension_fault_detection.spec import SPEC, Settings

__all__ = ["SPEC", "STUDIES", "Settings", "run", "stored_sizes", "validate"]

"""Chapter ``partial-state-observer`` (paper 000, Zheng, Chai, Peng & Li 2016): 10-DOF vertical
vehicle, LMI functional (partial-state) observer of the wheelset displacements.

``SPEC`` (the chapter's parameters), ``Settings`` (its typed settings), ``validate(settings)``
and ``run(settings, progress=None)`` are what the pipeline needs; the modules of the package are
the chapter's parts (``experiment`` is the whole computation, ``figures`` and ``tables`` draw
from its result).
"""

from railpaper.experiments.partial_state_observer.experiment import run, validate
from railpaper.experiments.partial_state_observer.spec import SPEC, Settings

__all__ = ["SPEC", "Settings", "run", "validate"]

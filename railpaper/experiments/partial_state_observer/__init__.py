"""Chapter ``partial-state-observer`` (paper 000, Zheng, Chai, Peng & Li 2016): 10-DOF vertical
vehicle, LMI functional (partial-state) observer of the wheelset displacements.

``SPEC`` (the chapter's parameters), ``Settings`` (its typed settings), ``validate(settings)``,
``run(settings, progress=None, record_map=...)`` and ``STUDIES`` (its per-record studies, which
the evidence store and the decisive run compute) are what the pipeline needs; the modules of the
package are the chapter's parts (``experiment`` is the whole computation, ``records`` its
per-record work, a map over seeds, ``evidence`` the reduce, ``figures`` and ``tables`` draw from
its result).
"""

from railpaper.experiments.partial_state_observer.experiment import run, validate
from railpaper.experiments.partial_state_observer.records import KALMAN_BASELINE, MONTE_CARLO
from railpaper.experiments.partial_state_observer.spec import SPEC, Settings

#: The chapter's per-record studies.
STUDIES = (MONTE_CARLO, *KALMAN_BASELINE.values())

__all__ = ["SPEC", "STUDIES", "Settings", "run", "validate"]

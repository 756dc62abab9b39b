"""Chapter ``rbpf-parameter-estimation`` (paper 003, Ding et al. 2014): RBPF versus augmented
EKF, on the Eq. (18) toy and the 16-state lateral vehicle, with the exact posterior beside.

``SPEC`` (the chapter's parameters), ``Settings`` (their typed values), ``validate(settings)``,
``run(settings, progress=None, record_map=...)``, ``STUDIES`` (its per-record studies, which
the evidence store and the decisive run compute) and the soundness of its filters against the
exact posterior (``POSTERIOR_OF``, ``soundness_columns``, ``estimator_of``: what the ledger's
decision procedures read) are what the pipeline needs; the modules of the
package are the chapter's parts (``experiment`` is the whole computation, ``figures`` and
``tables`` draw from its result).
"""

from railpaper.experiments.rbpf_parameter_estimation.experiment import STUDIES, run, validate
from railpaper.experiments.rbpf_parameter_estimation.soundness import (
    POSTERIOR_OF,
    estimator_of,
    soundness_columns,
)
from railpaper.experiments.rbpf_parameter_estimation.spec import SPEC, Settings

__all__ = ["POSTERIOR_OF", "SPEC", "STUDIES", "Settings", "estimator_of", "run",
           "soundness_columns", "validate"]

"""The control laws: the ``law`` parameter names a row of ``LAWS``, each a ``Law``
(``core.law.step_types``): its configuration error and its filter of the geometric moment, data
and a pure function of the step's terms and the model (``AttitudeController.control`` runs them).

- ``delay_robust`` (the default): the paper's law with each cone widened by the blind time, and
  the approach brake;
- ``paper``: the paper's law as published, the cones' log barrier in the configuration error;
- ``geometric``: Lee's geometric controller with the same gains and no barrier (the baseline);
- ``cbf``: the geometric baseline filtered by a control-barrier-function QP, each cone a pointing
  constraint of relative degree 2, solved exactly by its active set every step.

A new law is a file of its own and a row here, not a new loop; laws do not import each other.
"""
from geoctl_ros.core.law.cbf_law import CBF
from geoctl_ros.core.law.delay_robust_law import DELAY_ROBUST
from geoctl_ros.core.law.geometric_law import GEOMETRIC
from geoctl_ros.core.law.paper_law import PAPER

LAWS = {'delay_robust': DELAY_ROBUST, 'paper': PAPER, 'geometric': GEOMETRIC, 'cbf': CBF}

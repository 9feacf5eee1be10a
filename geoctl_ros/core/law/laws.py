"""The control laws, one signature: ``law(controller, R, Omega, dt, adapt, blind, brake) ->
ControlOutput`` (``geoctl_ros.core.law.control``); the ``law`` parameter names a row of ``LAWS``.

- ``delay_robust`` (the default): the paper's law with each cone widened by the blind time;
- ``paper``: the paper's law as published, the cones' log barrier in the configuration error;
- ``geometric``: Lee's geometric controller with the same gains and no barrier (the baseline);
- ``cbf``: the geometric baseline filtered by a control-barrier-function QP, each cone a pointing
  constraint of relative degree 2, solved exactly by its active set every step.
"""
from geoctl_ros.core.law.cbf_law import cbf_law
from geoctl_ros.core.law.delay_robust_law import delay_robust_law
from geoctl_ros.core.law.geometric_law import geometric_law
from geoctl_ros.core.law.paper_law import paper_law

# The control laws, one signature: law(controller, R, Omega, dt, adapt, blind, brake) ->
# ControlOutput (brake: the approach brake's inputs of the tick, or None).
# The ``law`` parameter names one; a new law is a file of its own and a row here, not a new loop.
LAWS = {'delay_robust': delay_robust_law, 'paper': paper_law, 'geometric': geometric_law,
        'cbf': cbf_law}

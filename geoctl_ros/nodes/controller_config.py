"""The controller node's configuration (a mixin of ``ControllerNode``): its setup built from its
parameters, whether anyone configured it, and run-time parameter changes, validated by the shared
schema before they touch the running controller.
"""
from geoctl_ros.nodes import ros_params
from geoctl_ros.params import (
    CHANGE_WHILE_ARMED,
    CONTROLLER,
    ConfigError,
    change_problem,
    configuration_given,
    controller_setup,
    resolve,
)


def build(values):
    """The controller setup of a node's parameters: cones defined but not yet in cones.names are
    allowed (they are being added, one parameter at a time, or came from a dump).
    """
    return controller_setup(resolve(CONTROLLER, values, staged_cones=True))


class ControllerConfiguration:
    """Configuration of the controller node: uses its ``loop`` and logger."""

    def _unconfigured(self, setup):
        """Why this node flies nothing it was given, or None: no parameter of its own reached it
        (no file, a launch file's missing params_file, which only warns and passes none, or a
        file whose sections name another node or namespace: its ``/**`` values alone do not
        configure a controller).
        """
        if (configuration_given(CONTROLLER, ros_params.file_overrides(self))
                or setup.loop.allow_default_configuration):
            return None
        return ('no configuration given for %s: no parameter file (or none addressed to this '
                'name and namespace), so every arm request is refused (give --params-file FILE '
                'with a section for it, or -p allow_default_configuration:=true to fly the '
                'built-in defaults deliberately)' % self.get_fully_qualified_name())

    def _validate(self, values, changed):
        """A run-time change: only gains and goals while armed (``CHANGE_WHILE_ARMED``), the
        whole configuration, and the set point now being flown (which may have come in on the
        topic) against the new cones.
        """
        if self.loop.supervisor.armed:
            problem = change_problem(changed, CHANGE_WHILE_ARMED, 'while disarmed')
            if problem:
                raise ConfigError([('armed', problem)])
        setup = build(values)
        problem = self.loop.reconfiguration_problem(setup)
        if problem:
            raise ConfigError([('cones', problem)])
        return setup

    def _apply(self, setup, changed):
        problem = self.loop.reconfigure(
            setup, setpoint_changed='setpoint' in changed,
            schedule_changed=any(n.startswith('setpoint_schedule.') for n in changed))
        if problem:       # validated before; only a set point that arrived since can do this
            self.get_logger().error('parameters not applied: ' + problem)
        else:
            self.get_logger().info('parameters applied: %s' % ', '.join(sorted(changed)))

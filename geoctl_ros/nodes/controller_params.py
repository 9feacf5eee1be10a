"""A node's view of the controller's cone and sensor parameters, asked for over the controller's
parameter services once it is up (the recorder stores them in its bag, the 3D view draws them).
"""
from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.parameter import parameter_value_to_python

from geoctl_ros.nodes.conversions import python_value

PREFIXES = ['cones', 'sensor_axis']


class ControllerParameters:
    """Asks the controller node for its cones.* and sensor_axis every period seconds until it
    answers, then calls on_values({name: value}) once.
    """

    def __init__(self, node, controller, on_values, period=1.0):
        controller = '/' + controller.strip('/')
        self._node = node
        self._list = node.create_client(ListParameters, controller + '/list_parameters')
        self._get = node.create_client(GetParameters, controller + '/get_parameters')
        self._on_values = on_values
        self._asking = False
        self._timer = node.create_timer(period, self._ask)

    def _ask(self):
        if self._asking or not self._list.service_is_ready():
            return
        self._asking = True
        request = ListParameters.Request()
        request.prefixes, request.depth = PREFIXES, 0
        self._list.call_async(request).add_done_callback(self._on_list)

    def _on_list(self, future):
        names = list(future.result().result.names) if future.result() else []
        if not names:
            self._asking = False
            return
        request = GetParameters.Request()
        request.names = names
        self._get.call_async(request).add_done_callback(lambda f: self._on_get(names, f))

    def _on_get(self, names, future):
        if future.result() is None:
            self._asking = False
            return
        self._node.destroy_timer(self._timer)
        self._on_values({n: python_value(parameter_value_to_python(v))
                         for n, v in zip(names, future.result().values)})

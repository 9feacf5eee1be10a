"""The controller node's supervisor without ROS: the loop and every decision it makes (input checks
and streams, arming and failsafes, gaps ridden through), the control tick, and what its
diagnostics say.
"""

"""The sensors: the inputs' conventions, whether the IMU and the motion capture agree, and the
calibration.
"""

"""The paper's law and its math: the cones and their barrier, the configuration error, the
controller and its laws, the gain condition, the approach brake, guidance round the cones, which
set points can be flown, the prediction over the measurements' age, and the testbed's mechanics
the law models.
"""

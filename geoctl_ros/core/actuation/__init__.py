"""Actuation: the airframe's effectiveness (what each rotor's thrust does), the allocation of a
moment to the rotors, the motors (thrust curve, the mixer with its lag compensation), and what
the controller and the nodes that drive the motors exchange (esc_wire: the armed state, the ESCs'
health, the motor_commands check).
"""

"""Actuation: the airframe's effectiveness (what each rotor's thrust does), the allocation of a
moment to the rotors, and the motors (thrust curve, the mixer with its lag compensation).
"""

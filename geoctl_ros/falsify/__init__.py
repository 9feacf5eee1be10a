"""Search-based falsification of the cone and of the settling (`./run falsify`; docs/safety.md,
"Falsification"): the envelope searched, the requirements in signal temporal logic, the search.
"""

"""Map quality: ``metrics`` against simulated truth (accuracy, F1, Brier, checks) and
``consistency`` of a map with its own log, for logs without truth.
"""

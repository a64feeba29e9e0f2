"""Map quality: ``metrics`` against simulated truth (accuracy, F1, Brier, checks), ``consistency``
of a map with its own log, and ``holdout``: scores of a map on scans held out of its making,
for logs with or without truth.
"""

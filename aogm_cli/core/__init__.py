"""Domain types and conversions, free of I/O: the error types, the grid (world <-> cell), robot
frames, a log and a finished map in memory (``log``, ``occupancy_map``), signals (``interrupts``).
"""

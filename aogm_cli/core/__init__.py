"""Domain types and conversions, free of I/O: the error type, the grid (world <-> cell), robot
frames, a log in memory (``log``) and a finished map in memory (``occupancy_map``).
"""

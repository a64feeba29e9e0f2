"""aogm: occupancy-grid maps from sonar readings (standard, EM and adaptive mappers).

The package is laid out along the flow of data:
world -> simulation -> logfile -> mapping -> mapfile -> evaluation -> report.
"""

__version__ = "0.1.0"

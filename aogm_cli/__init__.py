"""aogm: occupancy-grid maps from sonar readings (standard, EM and adaptive mappers).

The package is laid out along the flow of data: world -> simulation -> log -> mapping ->
map -> evaluation -> report, over ``core`` (domain types) and ``io`` (file formats).
"""

__version__ = "0.1.0"

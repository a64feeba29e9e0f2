"""The world a simulated robot drives through: typed configuration (``config``), the YAML loader
that validates it (``loader``), its solids (``solids``), the ray-castable scene (``scene``), the
truth raster (``truth``) and the path (``trajectory``); ``office`` generates a large office floor
as a world file.
"""

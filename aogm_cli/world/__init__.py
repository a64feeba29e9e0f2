"""The world a simulated robot drives through: typed configuration (``config``), the YAML
loader that validates it (``loader``), and its geometry and truth raster.
"""

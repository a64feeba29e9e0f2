"""The world a simulated robot drives through: typed configuration (``config``) validated by its YAML
``loader``, its ``solids``, the ray-castable ``scene``, the ``truth`` raster and the ``trajectory``;
``office`` generates a large office floor; ``simulation_cost`` what simulating a world would cost."""

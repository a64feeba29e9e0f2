"""Mapping: a log in, an occupancy map out, in three modes over the sensor models (``aogm_cli.sensor_models``):
``standard`` (log-odds, each cell on its own), ``em`` (Thrun's EM with forward models) and ``adaptive`` (EM
inside the detector's clusters, standard elsewhere); ``modes.map_source`` maps a log source, ``map_files`` a file."""

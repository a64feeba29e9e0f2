"""Mapping: a log in, an occupancy map out, in three modes over shared sensor models.

``standard`` (log-odds, each cell on its own), ``em`` (Thrun's EM with forward models) and
``adaptive`` (EM inside the detector's clusters, standard elsewhere) are one module each;
``sensor_models/`` holds the cone templates, the inverse and the forward model they share;
``modes.map_file`` is the one entry point the commands call.
"""

"""Every file format, in and out: atomic outputs, HDF5 and YAML inputs, the log, map and detector
files of CONTRACT.md, ROS map_server/map_saver maps, and the importers of real logs.
"""

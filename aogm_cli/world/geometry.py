"""World geometry compiled for the simulator, under the names callers import it by.

The work lives by concern: ``world.solids`` (the solids in world coordinates), ``world.scene``
(the ray-castable ``Scene``), ``world.truth`` (the truth raster), ``world.trajectory`` (the path).
"""

from __future__ import annotations

from aogm_cli.world.scene import DEFAULT_BUCKET_SIZE, MAX_BUCKETS, Scene, build_scene
from aogm_cli.world.solids import Solids, box_corners, wall_pieces, world_solids
from aogm_cli.world.trajectory import trajectory_poses
from aogm_cli.world.truth import truth_occupancy

__all__ = [
    "DEFAULT_BUCKET_SIZE",
    "MAX_BUCKETS",
    "Scene",
    "Solids",
    "box_corners",
    "build_scene",
    "trajectory_poses",
    "truth_occupancy",
    "wall_pieces",
    "world_solids",
]

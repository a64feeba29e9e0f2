"""EM's compiled kernels in bounded memory (``mapping.em`` drives them): the arrays' layout,
where each reading's cone lies, each reading's likelihood state, the arena of window
obstacles, and the sweep over tiles of regenerated cones (one module each)."""

from aogm_cli.mapping.em_kernels.layout import *  # noqa: F403
from aogm_cli.mapping.em_kernels.likelihood import (  # noqa: F401
    _find,
    _init_state,
    _join_parents,
    _objective,
    _residual_from_gains,
)
from aogm_cli.mapping.em_kernels.readings import (  # noqa: F401
    _box_of_cells,
    _far_gains,
    _reading_extent,
    _window_cells,
    _window_rows,
)
from aogm_cli.mapping.em_kernels.tiles import _sweep_tiles  # noqa: F401

"""EM's compiled kernels in bounded memory (``mapping.em`` drives them): the arrays' layout,
where each reading's cone lies, each reading's likelihood state, the arena of window
obstacles, and the sweep over tiles of regenerated cones (one module each; import from it)."""

from aogm_cli.mapping.em_kernels.layout import EMModel, EMReadings, EMState, row_groups  # noqa: F401
from aogm_cli.mapping.em_kernels.likelihood import _find  # noqa: F401

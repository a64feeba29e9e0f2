"""EM's compiled kernels in bounded memory (``mapping.em`` drives them): the arrays' layout
(``layout``), where each reading's cone lies (``extents``), each reading's likelihood state
(``likelihood``), the arena of window obstacles (``windows``) and the sweep over tiles (``tiles``)."""

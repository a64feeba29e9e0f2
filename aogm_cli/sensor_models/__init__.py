"""The models of a reading that mapping and scoring share: cone templates (``cone``), a narrow beam as a
ray (``ray``), the inverse model of standard mapping, the forward model of EM, and readings laid out
on a grid (``readings``). Below mapping: evaluation and training use them without the mapper."""

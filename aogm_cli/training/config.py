"""How the cluster detector is trained: the network's size, its fitting and the flag threshold's rule;
apart from ``fit`` (which loads scikit-learn) so that the command line reads its defaults cheaply."""

from __future__ import annotations

from dataclasses import dataclass

from aogm_cli.core.errors import InputError


@dataclass(frozen=True)
class TrainingConfig:
    """The network and how it is fitted: one hidden layer, sklearn's adam, a fixed seed."""

    hidden: int = 16  # units of the one hidden layer
    activation: str = "tanh"  # of the hidden layer: tanh, relu or logistic
    seed: int = 0  # MLPClassifier random_state (initial weights, batch order)
    alpha: float = 1e-4  # L2 penalty
    max_iter: int = 1000  # adam epochs at most
    # the threshold maximises F_beta on the training data (beta < 1 favours precision): a false
    # flag costs EM time inside a needless cluster, a missed one is mostly covered by the bands
    # of its flagged neighbours (docs/algorithms.md, "Where the defaults come from")
    beta: float = 0.25

    def __post_init__(self):
        if self.hidden < 1:
            raise InputError(f"expected a positive integer, got {self.hidden}", key="hidden")
        if self.activation not in ("tanh", "relu", "logistic"):
            raise InputError(f"expected tanh, relu or logistic, got {self.activation!r}", key="activation")
        if not self.beta > 0:
            raise InputError(f"expected a positive number, got {self.beta}", key="beta")

"""The paper's cluster detector: which readings sweep a cluttered or erroneous region (y = 1).

``features`` builds the network's input from neighbouring readings, ``labels`` derives y from
simulation truth, ``network`` reads/writes detector files and runs inference in numpy, and
``train`` fits the network with scikit-learn (imported only there).
"""

from aogm_cli.detector.features import FeatureSpec, features
from aogm_cli.detector.network import Detector, default_detector_path, load_detector, save_detector

__all__ = ["Detector", "FeatureSpec", "default_detector_path", "features", "load_detector", "save_detector"]

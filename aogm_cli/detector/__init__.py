"""The paper's cluster detector at mapping time: which readings sweep a cluttered or erroneous region
(y = 1). ``features`` builds the network's input, ``network`` runs it in numpy; training lives in
``aogm_cli.training``, the detector file in ``aogm_cli.io.detectorfile``."""

"""A real laser log end to end: the intel log (../shared/data) imports, maps as rays, and its
standard map agrees with its own readings (the issue's bar: 70% of in-range endpoints on cells
believed occupied)."""


import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.evaluation.consistency import log_consistency
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file

INTEL = "data/carmen/intel-corrected.log.gz"  # in ../shared


@pytest.fixture(scope="module")
def intel(tmp_path_factory, require):
    intel_log = require.shared(INTEL)
    folder = tmp_path_factory.mktemp("intel")
    log, m = folder / "intel.h5", folder / "intel_map.h5"
    runner = CliRunner()
    result = runner.invoke(main, ["import", "carmen", str(intel_log), "-o", str(log), "--max-range", "30", "-q"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(main, ["map", str(log), "--mode", "standard", "-o", str(m), "-q"])
    assert result.exit_code == 0, result.output
    return log, m


def test_intel_imports_as_a_laser_log(intel):
    with LogReader(intel[0]) as reader:
        assert reader.n_scans == 910 and reader.sensor.count == 180
        assert reader.sensor.kind == "laser" and reader.sensor.max_range == 30.0
        assert not reader.has_truth


def test_intel_standard_map_agrees_with_its_readings(intel):
    log, path = intel
    m = read_map_file(path)
    with LogReader(log) as reader:
        c = log_consistency(reader, m.grid, m.probability, m.observed)
    assert c["method"] == "endpoint" and c["readings"] > 150_000
    assert c["endpoint_occupied"] >= 0.70  # 0.892 when written
    assert c["endpoint_occupied_8"] >= 0.90  # 0.970
    assert c["free_contradicted"] <= 0.05  # 0.009
    # a building, not a smear: thin walls (a small share of the observed cells) around free rooms
    occupied = m.observed & (m.probability > 0.5)
    assert 0.005 < occupied.sum() / m.observed.sum() < 0.05  # 0.025
    assert np.mean(m.probability[m.observed] < 0.5) > 0.9

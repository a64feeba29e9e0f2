"""``aogm simulate`` end to end: the log file of CONTRACT.md, determinism, and bad input."""

from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.log import CAUSE_RANDOM, CAUSE_SPECULAR
from aogm_cli.io.logfile import read_log

WORLDS = Path(__file__).resolve().parents[1] / "worlds"


def simulate(tmp_path, world, name, seed=1, extra=()):
    out = tmp_path / name
    result = CliRunner().invoke(main, ["simulate", str(world), "-o", str(out), "--seed", str(seed), "--quiet", *extra])
    return result, out


def test_same_seed_gives_identical_datasets(tmp_path):
    r1, a = simulate(tmp_path, WORLDS / "corridor_door.yaml", "a.h5")
    r2, b = simulate(tmp_path, WORLDS / "corridor_door.yaml", "b.h5")
    r3, c = simulate(tmp_path, WORLDS / "corridor_door.yaml", "c.h5", seed=2)
    assert r1.exit_code == r2.exit_code == r3.exit_code == 0, r1.output
    with h5py.File(a) as fa, h5py.File(b) as fb, h5py.File(c) as fc:
        names = []
        fa.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
        for n in names:
            assert np.array_equal(fa[n][...], fb[n][...], equal_nan=True), n
        assert not np.array_equal(fa["scans/ranges"][...], fc["scans/ranges"][...], equal_nan=True)


def test_log_follows_the_contract(tmp_path):
    result, out = simulate(tmp_path, WORLDS / "corridor_door.yaml", "door.h5", extra=["--png", str(tmp_path / "t.png")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "t.png").stat().st_size > 1000
    with h5py.File(out) as f:
        assert f.attrs["format"] == "aogm-log" and f.attrs["format_version"] == 1
        assert f.attrs["seed"] == 1 and "aogm_version" in f.attrs and "source" in f.attrs
        t = f["scans/time"].shape[0]
        assert f["scans/pose"].shape == (t, 3) and f["scans/pose"].dtype == np.float64
        assert f["scans/ranges"].shape == (t, 24) and f["scans/ranges"].dtype == np.float32
        assert f["sensors/mount"].shape == (24, 3)
        assert f["sensors"].attrs["kind"] == "sonar"
        for k in ("beam_width", "min_range", "max_range", "noise_sigma"):
            assert k in f["sensors"].attrs
        assert f["truth/occupancy"].dtype == np.uint8 and f["truth/cause"].dtype == np.int8
        assert f["truth/ideal_range"].shape == (t, 24)
        for k in ("resolution", "origin", "world", "checks"):
            assert k in f["truth"].attrs
        ranges = f["scans/ranges"][...]
        cause = f["truth/cause"][...]
        assert np.all(np.isinf(ranges[cause == 1]))


def test_truth_puts_the_door_where_the_yaml_says(corridor_door_log):
    log = read_log(corridor_door_log)
    grid, occ = log.truth.grid, log.truth.occupancy
    row, _ = grid.world_to_cell(0.0, 2.0)
    _, cols = grid.world_to_cell(np.array([9.4, 9.6, 10.0, 10.4, 10.6]), 0.0)
    assert occ[row, cols].tolist() == [1, 0, 0, 0, 1]  # the 1.0 m door at x = 10
    r0, _ = grid.world_to_cell(0.0, 0.0)
    _, c5 = grid.world_to_cell(5.0, 0.0)
    assert occ[r0, c5] == 1 and occ[r0 + 10, c5] == 0  # the lower wall, free corridor above


def test_specular_corridor_has_more_erroneous_readings(tmp_path):
    shares = {}
    for name in ("corridor_door", "corridor_specular"):
        _, out = simulate(tmp_path, WORLDS / f"{name}.yaml", f"{name}.h5")
        cause = read_log(out).truth.cause
        shares[name] = np.mean(cause == CAUSE_SPECULAR) + np.mean((cause == 1) & ~np.isinf(read_log(out).truth.ideal_range))
        assert np.mean(cause == CAUSE_RANDOM) < 0.05
    assert shares["corridor_specular"] > 2 * shares["corridor_door"] + 0.05


@pytest.mark.parametrize(
    "text, key",
    [
        ("bounds: [0, 0, 10\n", "line"),
        ("bounds: [0, 0, 10, 5]\nwalls:\n  - points: [[0, 0], [1, 0]]\ntrajectory: {waypoints: [[1, 1], [2, 1]]}\nsonar: {beam_widht_deg: 30}\n",
         "sonar.beam_widht_deg"),
        ("bounds: [0, 0, 10, 5]\nwalls:\n  - points: [[0, 0], [1, 0]]\n    thickness: -0.1\ntrajectory: {waypoints: [[1, 1], [2, 1]]}\n",
         "walls[0].thickness"),
    ],
)
def test_bad_world_exits_2_names_file_and_key_and_leaves_no_output(tmp_path, text, key):
    world = tmp_path / "bad.yaml"
    world.write_text(text)
    result, out = simulate(tmp_path, world, "never.h5")
    assert result.exit_code == 2
    assert str(world) in result.output and key in result.output
    assert "Traceback" not in result.output
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bad.yaml"]
    assert world.read_text() == text


def test_missing_world_and_missing_output_folder(tmp_path):
    result, _ = simulate(tmp_path, tmp_path / "nope.yaml", "x.h5")
    assert result.exit_code == 2 and "no such file" in result.output
    result = CliRunner().invoke(main, ["simulate", str(WORLDS / "corridor_door.yaml"), "-o", str(tmp_path / "no" / "x.h5"), "-q"])
    assert result.exit_code == 2 and "does not exist" in result.output

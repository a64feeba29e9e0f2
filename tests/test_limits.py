"""Work sizes bounded before work starts: absurd worlds and logs are refused with exit 2 and the
estimate within seconds, --max-memory / --max-work let a borderline case through; warnings."""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.budget import Limits, parse_size
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.io.logfile import write_log
from aogm_cli.mapping.map_cost import map_estimate

WORLDS = Path(__file__).resolve().parent.parent / "worlds"
DOOR = WORLDS / "corridor_door.yaml"


def run(*args):
    t0 = time.perf_counter()
    r = CliRunner().invoke(main, [str(a) for a in args])
    return r, time.perf_counter() - t0


@pytest.fixture
def no_work(monkeypatch):
    """Fail if any simulation or mapping starts."""
    import aogm_cli.mapping.modes as modes
    import aogm_cli.simulation.sonar as sonar

    def boom(*a, **k):
        raise AssertionError("heavy work started")

    monkeypatch.setattr(sonar, "echo_block", boom)
    monkeypatch.setattr(modes, "warm_up", boom)
    monkeypatch.setattr(modes, "map_in_mode", boom)


def world(tmp_path, old, new) -> Path:
    p = tmp_path / "w.yaml"
    p.write_text(DOOR.read_text().replace(old, new))
    return p


def a_log(tmp_path, max_range=5.0, n=20) -> Path:
    rng = np.random.default_rng(0)
    pose = np.column_stack([np.linspace(0, 2, n), np.zeros(n), np.zeros(n)])
    ranges = rng.uniform(0.5, 3.0, (n, 8)).astype(np.float32)
    mount = np.column_stack([np.zeros(8), np.zeros(8), np.linspace(0, 2 * np.pi, 8, endpoint=False)])
    sensor = SensorSpec(mount=mount, kind="sonar", max_range=max_range)
    path = tmp_path / "log.h5"
    write_log(path, Log(np.arange(n, dtype=float), pose, ranges, sensor, source="test"))
    return path


def test_parse_size():
    assert parse_size("16G") == 16e9 and parse_size("500MB") == 5e8 and parse_size("2e9") == 2e9
    with pytest.raises(ValueError):
        parse_size("lots")


def test_a_slow_speed_is_refused_with_the_estimate(tmp_path, no_work):
    # 9e6 scans, under the loader's 1e7 (speed: 1.0e-9 is refused by it, naming trajectory: test_bad_files)
    r, dt = run("simulate", world(tmp_path, "speed: 0.3", "speed: 4.0e-6"), "-o", tmp_path / "x.h5")
    assert r.exit_code == 2 and dt < 3, r.output
    assert "GB of memory (limit 16 GB)" in r.output and "--max-memory" in r.output
    assert "Traceback" not in r.output and not (tmp_path / "x.h5").exists()


def test_many_sub_rays_are_refused_by_the_work_limit(tmp_path, no_work):
    # the loader's most sub-rays (1000) on a slow drive (3e6 scans, 8.7 GB): 2e11 ray casts
    slow = world(tmp_path, "count: 24", "count: 24\n  sub_rays: 1000")
    slow.write_text(slow.read_text().replace("speed: 0.3", "speed: 1.2e-5"))
    r, dt = run("simulate", slow, "-o", tmp_path / "x.h5")
    assert r.exit_code == 2 and dt < 3, r.output
    assert "ray casts" in r.output and "--max-work" in r.output


def test_huge_sonar_count_is_refused(tmp_path, no_work):
    r, _ = run("simulate", world(tmp_path, "count: 24", "count: 10000000"), "-o", tmp_path / "x.h5")
    assert r.exit_code == 2 and "sonar.count" in r.output


def test_max_work_lets_a_borderline_simulation_through(tmp_path):
    w = world(tmp_path, "count: 24", "count: 24\n  sub_rays: 3")
    r, _ = run("simulate", w, "-o", tmp_path / "x.h5", "--max-work", "1000")
    assert r.exit_code == 2 and "limit 1000" in r.output
    r, _ = run("simulate", w, "-o", tmp_path / "x.h5", "--max-work", "1e7", "-q")
    assert r.exit_code == 0, r.output


def test_a_log_with_a_huge_max_range_is_refused_before_mapping(tmp_path, no_work):
    log = a_log(tmp_path, max_range=1e6)
    for mode in ("standard", "em", "adaptive"):
        r, dt = run("map", log, "--mode", mode, "-o", tmp_path / "m.h5")
        assert r.exit_code == 2 and dt < 5, r.output
        assert "of memory (limit 16 GB)" in r.output and "log.h5" in r.output


def test_a_fine_resolution_is_refused_and_max_memory_raises_the_limit(tmp_path, no_work):
    log = a_log(tmp_path)
    r, _ = run("map", log, "--mode", "em", "--resolution", "1e-4", "-o", tmp_path / "m.h5")
    assert r.exit_code == 2 and "--resolution: 0.0001 m is too fine" in r.output  # the option that set it
    assert "of memory (limit 16 GB)" in r.output
    r, _ = run("map", log, "--mode", "standard", "-o", tmp_path / "m.h5", "--max-memory", "1k")
    assert r.exit_code == 2 and "limit 1 kB" in r.output


def test_max_memory_lets_a_borderline_map_through(tmp_path):
    log = a_log(tmp_path)
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.params import MapParams

    with LogReader(log) as reader:
        need = map_estimate(reader, "em", MapParams()).memory
    r, _ = run("map", log, "--mode", "em", "-o", tmp_path / "m.h5", "--max-memory", str(need * 0.9))
    assert r.exit_code == 2
    r, _ = run("map", log, "--mode", "em", "-o", tmp_path / "m.h5", "--max-memory", str(need * 1.1), "-q")
    assert r.exit_code == 0, r.output


def test_compare_refuses_before_mapping(tmp_path, no_work):
    log = a_log(tmp_path, max_range=1e6)
    r, dt = run("compare", log, "--modes", "standard")
    assert r.exit_code == 2 and dt < 5 and "of memory" in r.output


def test_bundled_worlds_and_intel_sized_maps_are_well_within_the_defaults(tmp_path):
    from aogm_cli.world.loader import load_world
    from aogm_cli.world.simulation_cost import simulation_estimate

    limits = Limits()
    for path in WORLDS.glob("*.yaml"):
        e = simulation_estimate(load_world(path))
        assert e.memory < limits.max_memory / 100 and e.work < limits.work_limit(e.unit) / 100


def test_warnings_are_silenced_unless_debug(tmp_path, monkeypatch):
    import aogm_cli.mapping.modes as modes

    real = modes.map_in_mode

    def noisy(*a, **k):
        warnings.warn("invalid value encountered in divide", RuntimeWarning, stacklevel=1)
        return real(*a, **k)

    monkeypatch.setattr(modes, "map_in_mode", noisy)
    log = a_log(tmp_path)
    r = CliRunner().invoke(main, ["map", str(log), "--mode", "standard", "-o", str(tmp_path / "m.h5")])
    assert r.exit_code == 0 and "Warning" not in r.stderr, r.stderr
    r = CliRunner().invoke(
        main, ["--debug", "map", str(log), "--mode", "standard", "-o", str(tmp_path / "m2.h5")])
    assert r.exit_code == 0 and "RuntimeWarning" in r.stderr


def test_a_map_that_does_not_fit_names_what_makes_it_fit(tmp_path):
    # the grid fits, the em map does not: the refusal names the resolution and the readings' share
    log = a_log(tmp_path)
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.params import MapParams

    with LogReader(log) as reader:
        need = map_estimate(reader, "em", MapParams()).memory
    r, _ = run("map", log, "--mode", "em", "-o", tmp_path / "m.h5", "--max-memory", str(need * 0.9))
    assert r.exit_code == 2 and not (tmp_path / "m.h5").exists()
    assert "--max-memory" in r.output and "a coarser --resolution" in r.output
    assert "the readings' share" in r.output and "standard mode" in r.output
    r, _ = run("map", log, "--mode", "standard", "-o", tmp_path / "m.h5", "--max-memory", "1k")
    assert r.exit_code == 2 and "a coarser --resolution" in r.output and "readings' share" not in r.output

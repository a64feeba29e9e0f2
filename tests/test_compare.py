"""``aogm compare`` end to end on tiny simulated corridors: JSON, map reuse, gates, figure."""

import dataclasses
import hashlib
import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from aogm_cli import map_files
from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.evaluation.metrics import map_metrics, run_checks
from aogm_cli.evaluation.planner import planner_metrics
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import parse_world

METRICS = ("accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "brier", "ece")
PLANNER = ("leak", "block", "surface_recall")  # against the truth, for the default --robot-radius 0.2


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def logs(tmp_path_factory, tiny_door_world):
    """Two ~20-scan logs of one small corridor world (seeds 1 and 2)."""
    folder = tmp_path_factory.mktemp("logs")
    world = parse_world(yaml.safe_load(tiny_door_world), file="tiny_door.yaml", text=tiny_door_world)
    paths = []
    for seed in (1, 2):
        log = simulate(world, seed=seed)
        assert 15 <= log.n_scans <= 25
        path = folder / f"door_{seed}.h5"
        write_log(path, log)
        paths.append(path)
    return paths


@pytest.fixture(scope="module")
def compared(logs, tmp_path_factory):
    """``compare --modes standard,em`` on both logs, with --json and --maps-dir."""
    out = tmp_path_factory.mktemp("cmp")
    result = run("compare", *logs, "--modes", "standard,em", "--json", out / "r.json", "--maps-dir", out / "maps", "-q")
    assert result.exit_code == 0, result.output
    return out, json.loads((out / "r.json").read_text()), result.output


def sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def independent_metrics(map_path, log_path):
    """Metrics straight from the files: the map's arrays and the log's truth, via map_metrics."""
    with h5py.File(map_path) as f:
        probability, observed = f["map/probability"][...], f["map/observed"][...]
        runtime = float(f.attrs["runtime_s"])
        origin, resolution = f["map"].attrs["origin"], float(f["map"].attrs["resolution"])
    with h5py.File(log_path) as f:
        truth = f["truth/occupancy"][...]
        checks = json.loads(f["truth"].attrs["checks"])
        poses = f["scans/pose"][...]
    metrics = map_metrics(probability, observed, truth)
    grid = GridSpec(float(origin[0]), float(origin[1]), resolution, *probability.shape)
    metrics["checks"] = run_checks(grid, probability, observed, checks)
    metrics.update(planner_metrics(grid, probability, observed, truth, poses, 0.2))
    return metrics, runtime


def test_json_follows_the_contract_and_matches_the_map_files(logs, compared):
    out, data, _ = compared
    assert set(data) == {"format", "format_version", "aogm_version", "results", "provenance", "summary"}
    assert data["aogm_version"] == "0.1.0"
    assert (data["format"], data["format_version"]) == ("aogm-compare", 1)
    assert [(r["log"], r["mode"]) for r in data["results"]] == [
        (str(logs[0]), "standard"), (str(logs[0]), "em"), (str(logs[1]), "standard"), (str(logs[1]), "em")
    ]
    for r in data["results"]:
        assert set(r) == {"log", "world", "mode", "truth", "runtime_s", "metrics", "params", "detector", "calibration",
                          "log_content"}
        assert r["truth"] is True
        if r["mode"] == "em":  # the forward model learned from the log; the map's parameters stay as configured
            assert set(r["calibration"]["final"]) == {"sigma", "p_rand", "p_hit", "p_max"}
            assert r["params"]["em"]["sigma"] == 0.03
        else:
            assert r["calibration"] is None
        assert r["params"]["mode"] == r["mode"] and r["detector"] is None  # no adaptive map here
        assert r["world"] == "tiny_door"
        assert set(r["metrics"]) == set(METRICS) | set(PLANNER) | {"checks"}
        stem = r["log"].rsplit("/", 1)[-1][:-3]
        expected, runtime = independent_metrics(out / "maps" / f"{stem}_{r['mode']}.h5", r["log"])
        for key in METRICS + PLANNER:
            assert r["metrics"][key] == pytest.approx(expected[key], abs=1e-12)
        assert r["metrics"]["checks"] == expected["checks"]
        assert [c["name"] for c in r["metrics"]["checks"]] == ["door_passable", "through_wall"]
        assert r["runtime_s"] == runtime and r["runtime_s"] > 0


def test_a_results_file_without_ece_reads_back_with_ece_null(compared, tmp_path):
    """A --json file written before the ECE was measured reads back, its ECE null (a gate naming
    it fails, NaN); the same file with it passes."""
    out, data, _ = compared
    old = json.loads(json.dumps(data))
    for r in old["results"]:
        del r["metrics"]["ece"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    result = run("compare", "--from-json", tmp_path / "old.json", "--require", "em.ece <= 1", "--json",
                 tmp_path / "again.json")
    assert result.exit_code == 1 and "em.ece <= 1  (nan <= 1; not a number)" in result.output
    assert all(r["metrics"]["ece"] is None for r in json.loads((tmp_path / "again.json").read_text())["results"])
    assert run("compare", "--from-json", out / "r.json", "--require", "em.ece <= 1", "-q").exit_code == 0


def test_table_names_worlds_modes_and_relative_runtime(compared):
    _, data, output = compared
    # two logs of one world: the label adds the file stem
    assert "tiny_door (door_1)" in output and "tiny_door (door_2)" in output
    assert output.count("x1.00") >= 2  # each standard map relative to itself
    em = data["results"][1]
    ratio = em["runtime_s"] / data["results"][0]["runtime_s"]
    assert f"x{ratio:.2f}" in output
    passed = sum(c["passed"] for c in em["metrics"]["checks"])
    assert f"{passed}/2" in output


def test_map_files_give_the_same_numbers_without_mapping(logs, compared, monkeypatch, tmp_path):
    out, data, _ = compared

    def no_mapping(*args, **kwargs):
        raise AssertionError("a map was computed again")

    monkeypatch.setattr(map_files, "map_file", no_mapping)
    maps = sorted((out / "maps").glob("*.h5"))
    assert len(maps) == 4
    result = run("compare", *maps, "--json", tmp_path / "again.json", "-q")  # modes from the map files
    assert result.exit_code == 0, result.output
    again = json.loads((tmp_path / "again.json").read_text())
    assert again.pop("provenance")["inputs"] == [{"path": str(m), "sha256": sha256(m)} for m in maps] + [
        {"path": str(log), "sha256": sha256(log)} for log in logs]  # the maps given, then the logs they name
    assert again == {k: v for k, v in data.items() if k != "provenance"}
    # a log together with one of its maps: only the missing mode is mapped
    monkeypatch.undo()
    result = run("compare", logs[0], out / "maps" / "door_1_em.h5", "--modes", "standard,em", "--json", tmp_path / "mix.json", "-q")
    assert result.exit_code == 0, result.output
    mixed = json.loads((tmp_path / "mix.json").read_text())["results"]
    assert mixed[1] == data["results"][1]
    assert "file " in result.output and "door_1_em.h5" in result.output


def test_parallel_jobs_give_the_same_metrics(logs, compared, tmp_path):
    _, data, _ = compared
    result = run("compare", *logs, "--modes", "standard,em", "--jobs", 2, "--json", tmp_path / "p.json", "-q")
    assert result.exit_code == 0, result.output
    parallel = json.loads((tmp_path / "p.json").read_text())["results"]
    assert [r["metrics"] for r in parallel] == [r["metrics"] for r in data["results"]]


def test_gates_pass_and_fail(logs, compared, tmp_path):
    out, data, _ = compared
    maps = sorted((out / "maps").glob("door_1_*.h5"))
    ok = run("compare", *maps, "--require", "em.accuracy >= 0", "--require", "standard.runtime > 0", "-q")
    assert ok.exit_code == 0, ok.output
    assert "gates: 2 of 2 passed" in ok.output
    bad = run("compare", *maps, "--require", "em.accuracy >= standard.accuracy + 2", "--json", tmp_path / "r.json",
              "--figure", tmp_path / "f.png", "-q")
    assert bad.exit_code == 1
    em, std = data["results"][1]["metrics"]["accuracy"], data["results"][0]["metrics"]["accuracy"]
    assert f"FAILED tiny_door: em.accuracy >= standard.accuracy + 2  ({em:.6g} >= {std:.6g} + 2" in bad.output
    assert "1 of 1 gates failed" in bad.output
    assert (tmp_path / "r.json").exists() and (tmp_path / "f.png").exists()  # written before exit 1


def test_require_checks_fails_on_a_failed_check(compared):
    out, _, _ = compared
    maps = sorted((out / "maps").glob("door_1_*.h5"))
    result = run("compare", *maps, "--require-checks", "em", "-q")
    assert result.exit_code == 1  # through_wall can never pass: the far side is unobserved
    assert "FAILED tiny_door: em checks" in result.output and "through_wall" in result.output


@pytest.mark.parametrize(
    "args, words",
    [
        (["--require", "em.accuracy >= (standard.accuracy"], "--require"),
        (["--require", "em.acc > 0"], "unknown metric 'acc'"),
        (["--require", "adaptive.accuracy > 0", "--modes", "standard,em"], "'adaptive' is not among the modes"),
        (["--modes", "standard,emm"], "--modes"),
        (["--require-checks", "adaptive", "--modes", "standard,em"], "--require-checks"),
    ],
)
def test_malformed_gates_exit_2_before_mapping(logs, tmp_path, monkeypatch, args, words):
    def no_mapping(*a, **k):
        raise AssertionError("mapping started")

    monkeypatch.setattr(map_files, "map_file", no_mapping)
    result = run("compare", logs[0], *args, "--json", tmp_path / "r.json", "-q")
    assert result.exit_code == 2, result.output
    assert words in result.output and "Traceback" not in result.output
    assert not (tmp_path / "r.json").exists()


def test_figure_is_a_png(compared, tmp_path):
    out, _, _ = compared
    result = run("compare", *sorted((out / "maps").glob("*.h5")), "--figure", tmp_path / "cmp.png", "-q")
    assert result.exit_code == 0, result.output
    data = (tmp_path / "cmp.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_map_whose_log_is_missing_exits_2(compared, tmp_path):
    out, _, _ = compared
    lone = tmp_path / "lone.h5"
    shutil.copy(out / "maps" / "door_1_em.h5", lone)
    with h5py.File(lone, "a") as f:
        f.attrs["source_log"] = "nowhere/ghost.h5"
    result = run("compare", lone, "-q")
    assert result.exit_code == 2 and "source_log" in result.output and "ghost.h5" in result.output


def test_a_log_without_truth_has_no_truth_metrics(logs, tmp_path):
    log = read_log(logs[0])
    bare = tmp_path / "bare.h5"
    write_log(bare, dataclasses.replace(log, truth=None))
    params = tmp_path / "p.yaml"
    params.write_text("resolution: 0.2\n")
    result = run("compare", bare, "--modes", "standard", "--params", params, "--json", tmp_path / "r.json",
                 "--require", "standard.runtime > 0", "--require", "standard.accuracy > 0.5", "-q")
    assert result.exit_code == 1
    assert "FAILED bare: standard.accuracy > 0.5  (n/a > 0.5; standard.accuracy not available)" in result.output
    (r,) = json.loads((tmp_path / "r.json").read_text())["results"]
    assert r["world"] == "bare" and r["runtime_s"] > 0
    assert r["metrics"] == {"walls_kept": 1.0, "leak_vs_standard": 0.0, "far_leak": 0.0}  # the standard map itself
    assert "n/a" in result.output


def test_params_reach_every_mapping(logs, tmp_path):
    params = tmp_path / "p.yaml"
    params.write_text("inverse_model: {l_occ: 1.3}\n")
    result = run("compare", logs[0], "--modes", "standard", "--params", params, "--maps-dir", tmp_path / "m", "-q")
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "m" / "door_1_standard.h5") as f:
        assert json.loads(f.attrs["params"])["inverse_model"]["l_occ"] == 1.3
        assert np.isfinite(f["map/probability"][...]).all()


def test_adaptive_mode_takes_the_detector_and_draws_clusters(logs, tmp_path):
    """compare passes --detector to the adaptive mapper (here the flag-every-reading baseline),
    records it in the map and the JSON, and reports the mode beside standard."""
    result = run("compare", logs[0], "--modes", "standard,adaptive", "--detector", "all", "--json", tmp_path / "r.json",
                 "--figure", tmp_path / "f.png", "--maps-dir", tmp_path / "m", "-q")
    assert result.exit_code == 0, result.output
    rows = json.loads((tmp_path / "r.json").read_text())["results"]
    assert [r["mode"] for r in rows] == ["standard", "adaptive"]
    with h5py.File(tmp_path / "m" / "door_1_adaptive.h5") as f:
        assert json.loads(f.attrs["params"])["detector"] == "all"
        assert f.attrs["mode"] == "adaptive" and f["map/clusters"][...].max() > 0
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"


def test_results_are_small_records_unless_a_figure_or_maps_dir_needs_the_maps(logs, tmp_path):
    """Each task maps and evaluates where it runs; its map comes back only when asked for."""
    from aogm_cli.map_files import resolve_params
    from aogm_cli.report import compare as lib
    from aogm_cli.report.scoring import CompareJob

    entries = lib.collect_inputs([str(logs[0])])
    job = CompareJob(resolve_params(None, {"calibration": {"enabled": False}}))
    small, failed = lib.run_comparison(entries, ("standard", "em"), job, keep_maps=False)
    full, _ = lib.run_comparison(entries, ("standard", "em"), job, keep_maps=True)
    assert not failed and [r.map for r in small] == [None, None]
    assert all(r.map is not None for r in full)
    assert [r.metrics for r in small] == [r.metrics for r in full]
    in_dir, _ = lib.run_comparison(entries, ("standard",), job, maps_dir=str(tmp_path), keep_maps=False)
    assert in_dir[0].map is not None and in_dir[0].map_file == str(tmp_path / f"{logs[0].stem}_standard.h5")


def test_the_json_follows_its_schema(compared, require):
    # docs/schemas/compare.schema.json: what scripts may rely on in `aogm compare --json`
    jsonschema = require.module("jsonschema")
    schema = json.loads((Path(__file__).resolve().parents[1] / "docs" / "schemas" / "compare.schema.json").read_text())
    _, data, _ = compared
    jsonschema.validate(data, schema)
    broken = {**data, "results": [{**data["results"][0], "mode": "magic"}]}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, schema)


def test_em_and_adaptive_share_one_calibration_per_log(logs, tmp_path):
    # with calibration on, the em map takes the model the adaptive map of the same log learned;
    # its file says so, records calibration as configured (on), and is taken back by --resume
    maps = tmp_path / "maps"
    args = ["compare", logs[0], "--modes", "em,adaptive", "--maps-dir", maps, "--json", tmp_path / "r.json", "-q"]
    result = run(*args)
    assert result.exit_code == 0, result.output
    em, adaptive = (read_map_file(maps / f"door_1_{mode}.h5") for mode in ("em", "adaptive"))
    assert "made_by" not in adaptive.stats["calibration"] and em.stats["calibration"]["made_by"] == "adaptive"
    assert adaptive.stats["calibration"]["final"] == em.stats["calibration"]["final"]
    assert em.learned == {**adaptive.learned, "origin": "the adaptive map of this log"}  # the em map took it all
    assert em.params["em"] == adaptive.params["em"] and em.params["calibration"]["enabled"] is True  # as configured
    # its runtime counts the calibration it took, as the adaptive map timed it
    assert em.stats["phase_seconds"]["calibration"] >= adaptive.stats["phase_seconds"]["calibration"] > 0
    assert em.runtime_s == pytest.approx(sum(em.stats["phase_seconds"].values()), rel=1e-9)
    again = run(*args[:-1], "--resume")  # not quiet: it says what it took
    assert again.exit_code == 0 and "resume: 2 map(s)" in again.output, again.output
    # alone (or with --no-calibrate) each mode does its own
    alone = run("compare", logs[0], "--modes", "em", "--maps-dir", tmp_path / "alone", "-q")
    assert alone.exit_code == 0, alone.output
    assert "made_by" not in read_map_file(tmp_path / "alone" / "door_1_em.h5").stats["calibration"]


def test_jobs_share_the_cores_among_their_threads(monkeypatch):
    # compare --jobs J: each worker's EM sweeps take cores // J threads unless --threads says
    from aogm_cli.cli import compare as compare_cli
    from aogm_cli.core import budget

    monkeypatch.setattr(budget.os, "sched_getaffinity", lambda pid: set(range(8)), raising=False)
    assert compare_cli._threads(None, 1) is None  # one process: every core (Limits' default)
    assert compare_cli._threads(None, 2) == 4 and compare_cli._threads(None, 3) == 2
    assert compare_cli._threads(None, 16) == 1
    assert compare_cli._threads(3, 2) == 3
    assert budget.Limits(threads=None).thread_count() == 8 and budget.Limits(threads=2).thread_count() == 2

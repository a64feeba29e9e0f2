"""``aogm compare --csv`` and ``--from-json``: the CSV table against the JSON, and the JSON of
earlier runs read back, merged, printed and gated without mapping again."""

import dataclasses
import hashlib
import json
import shutil

import h5py
import pytest
import yaml
from click.testing import CliRunner

from aogm_cli import map_files
from aogm_cli.cli import main
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.report import scoring
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import parse_world

HALL = """
name: tiny_hall
bounds: [-0.5, -0.5, 5.0, 3.0]
truth_resolution: 0.1
walls:
  - points: [[0, 0], [4.5, 0], [4.5, 2.5], [0, 2.5], [0, 0]]
  - points: [[1.5, 2.5], [1.5, 1.4]]
boxes:
  - {center: [3.2, 0.6], size: [0.5, 0.4]}
trajectory:
  waypoints: [[0.6, 0.8], [3.9, 1.5]]
  speed: 0.6
  scan_period: 0.3
sonar: {count: 12, max_range: 3.0}
checks:
  - name: along
    passable: {from: [0.6, 0.8], to: [2.5, 1.0], robot_radius: 0.1}
  - name: into_the_wall
    passable: {from: [0.6, 0.8], to: [0.6, 2.8], robot_radius: 0.1}
"""
FIXED = ["log", "world", "mode", "truth", "runtime_s", "runtime_vs_standard", "accuracy", "occupied_precision",
         "occupied_recall", "occupied_f1", "brier", "ece", "checks_passed", "leak", "block", "surface_recall", "walls_kept",
         "leak_vs_standard", "far_leak", "consistency_method", "consistency_readings",
         "consistency_endpoint_occupied", "consistency_endpoint_occupied_8", "consistency_endpoint_free",
         "consistency_free_cells", "consistency_free_contradicted", "holdout_auc", "holdout_auc_band", "holdout_loglik",
         "holdout_readings", "holdout_scans", "learned_sigma", "learned_p_rand", "learned_p_hit", "learned_p_max",
         "learned_from_readings"]
LEARNED = ("sigma", "p_rand", "p_hit", "p_max")
FAILING = "em.accuracy >= standard.accuracy + 2"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def number(cell):
    return None if cell == "" else float(cell)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Two short logs of one small hall (seeds 1 and 2)."""
    folder = tmp_path_factory.mktemp("logs")
    world = parse_world(yaml.safe_load(HALL), file="tiny_hall.yaml", text=HALL)
    paths = []
    for seed in (1, 2):
        path = folder / f"hall_{seed}.h5"
        write_log(path, simulate(world, seed=seed))
        paths.append(path)
    return paths


@pytest.fixture(scope="module")
def runs(logs, tmp_path_factory):
    """``compare --modes standard,em`` of each log on its own: a.json and a.csv (with a failing
    gate: exit 1 after writing), b.json."""
    out = tmp_path_factory.mktemp("runs")
    a = run("compare", logs[0], "--modes", "standard,em", "--json", out / "a.json", "--csv", out / "a.csv",
            "--require", FAILING, "-q")
    assert a.exit_code == 1, a.output
    b = run("compare", logs[1], "--modes", "standard,em", "--json", out / "b.json", "-q")
    assert b.exit_code == 0, b.output
    return out, a.output


def without_provenance(doc):
    """The document without its provenance (the command and the time of the run that wrote it)."""
    return {k: v for k, v in doc.items() if k != "provenance"}


def sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def no_mapping(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a map was computed")

    monkeypatch.setattr(map_files, "map_file", refuse)
    monkeypatch.setattr(scoring, "map_one", refuse)


def test_the_csv_has_a_row_per_log_and_mode_equal_to_the_json(runs, read_csv):
    out, _ = runs
    doc = json.loads((out / "a.json").read_text())
    header, rows = read_csv(out / "a.csv")
    assert header == [*FIXED, "check:along", "check:into_the_wall", "statistic"]
    assert [(r["log"], r["mode"]) for r in rows] == [(r["log"], r["mode"]) for r in doc["results"]]
    _, summary = read_csv(out / "a.csv", summary=True)  # the summary's rows: here of one log
    mean = next(r for r in summary if (r["world"], r["mode"], r["statistic"]) == ("tiny_hall", "em", "mean"))
    assert float(mean["accuracy"]) == doc["results"][1]["metrics"]["accuracy"] == doc["summary"]["all"]["modes"][
        "em"]["accuracy"]["mean"]
    standard_runtime = doc["results"][0]["runtime_s"]
    for row, result in zip(rows, doc["results"], strict=True):
        metrics = result["metrics"]
        assert row["world"] == result["world"] == "tiny_hall" and row["truth"] == "true"
        assert float(row["runtime_s"]) == result["runtime_s"]
        assert float(row["runtime_vs_standard"]) == result["runtime_s"] / standard_runtime
        for key in ("accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "brier", "leak", "block",
                    "surface_recall"):
            assert float(row[key]) == metrics[key]
        assert row["walls_kept"] == row["leak_vs_standard"] == row["far_leak"] == ""  # against the standard map: no truth
        checks = {c["name"]: c["passed"] for c in metrics["checks"]}
        assert float(row["checks_passed"]) == sum(checks.values()) / 2
        assert {n: row[f"check:{n}"] for n in checks} == {n: "true" if p else "false" for n, p in checks.items()}
        assert row["check:into_the_wall"] == "false"
        assert all(row[k] == "" for k in FIXED if k.startswith(("consistency_", "holdout_")))
        if result["mode"] == "em":  # the model calibration learned; the map's parameters stay as configured
            assert {k: float(row[f"learned_{k}"]) for k in LEARNED} == result["calibration"]["final"]
            assert result["params"]["em"]["sigma"] == 0.03 != result["calibration"]["final"]["sigma"]
            assert int(row["learned_from_readings"]) == result["calibration"]["readings_used"] > 0
        else:
            assert result["calibration"] is None
            assert all(row[f"learned_{k}"] == "" for k in LEARNED) and row["learned_from_readings"] == ""


def test_from_json_merges_prints_and_gates_without_mapping(logs, runs, tmp_path, monkeypatch, read_csv):
    out, _ = runs
    no_mapping(monkeypatch)
    a, b = (json.loads((out / name).read_text()) for name in ("a.json", "b.json"))
    result = run("compare", "--from-json", out / "a.json", out / "b.json", "--json", tmp_path / "merged.json",
                 "--csv", tmp_path / "merged.csv", "--require", "em.accuracy >= 0.5", "--require", "standard.runtime > 0",
                 "--require-checks", "em")
    assert result.exit_code == 1, result.output  # the check into_the_wall fails on both logs
    assert "tiny_hall (hall_1)" in result.output and "tiny_hall (hall_2)" in result.output
    assert "json a.json" in result.output and "json b.json" in result.output and "x1.00" in result.output
    assert "FAILED tiny_hall (hall_2): em checks  (1/2 passed; failed: into_the_wall)" in result.output
    assert "gates: 4 of 6 passed" in result.output
    merged = json.loads((tmp_path / "merged.json").read_text())
    assert merged["results"] == a["results"] + b["results"]  # the union, unchanged
    assert merged["summary"]["all"]["logs"] == 2 and a["summary"]["all"]["logs"] == 1  # the summary of the union
    assert without_provenance({**merged, "results": [], "summary": None}) == without_provenance(
        {**a, "results": [], "summary": None})
    assert merged["provenance"]["inputs"] == [{"path": str(out / n), "sha256": sha256(out / n)} for n in ("a.json", "b.json")]
    assert a["provenance"]["inputs"][0]["sha256"] == sha256(logs[0])
    header, rows = read_csv(tmp_path / "merged.csv")
    assert header == read_csv(out / "a.csv")[0] and len(rows) == 4
    assert rows[:2] == read_csv(out / "a.csv")[1]  # the same cells as the run that mapped
    # merged again: the same document
    again = run("compare", "--from-json", tmp_path / "merged.json", "--json", tmp_path / "again.json", "-q")
    assert again.exit_code == 0, again.output
    assert without_provenance(json.loads((tmp_path / "again.json").read_text())) == without_provenance(merged)


def test_a_failed_gate_reads_as_in_the_run_that_mapped(runs, tmp_path, monkeypatch):
    out, original = runs
    no_mapping(monkeypatch)
    result = run("compare", "--from-json", out / "a.json", "--require", FAILING, "--csv", tmp_path / "r.csv", "-q")
    assert result.exit_code == 1
    failed = [line for line in original.splitlines() if line.startswith(("FAILED", "gates:"))]
    assert len(failed) == 2 and failed == [line for line in result.output.splitlines()
                                           if line.startswith(("FAILED", "gates:"))]
    assert (tmp_path / "r.csv").read_bytes() == (out / "a.csv").read_bytes()  # written before exit 1
    hint = run("compare", out / "a.json", "-q")  # without --from-json
    assert hint.exit_code == 2 and "a.json: a JSON file" in hint.output and "--from-json" in hint.output


def test_without_truth_and_with_holdout_the_csv_and_json_come_back_the_same(logs, tmp_path, monkeypatch, read_csv):
    bare = tmp_path / "bare.h5"
    write_log(bare, dataclasses.replace(read_log(logs[0]), truth=None))
    params = tmp_path / "p.yaml"
    params.write_text("resolution: 0.1\n")
    first = run("compare", bare, "--modes", "standard,em", "--holdout", 0.2, "--params", params, "--json",
                tmp_path / "h.json", "--csv", tmp_path / "h.csv", "--maps-dir", tmp_path / "maps", "-q")
    assert first.exit_code == 0, first.output
    with h5py.File(tmp_path / "maps" / "bare_em.h5") as f:  # the maps record the run's provenance too
        assert {"path": str(bare), "sha256": sha256(bare)} in json.loads(f.attrs["provenance"])["inputs"]
    header, rows = read_csv(tmp_path / "h.csv")
    assert header == [*FIXED, "statistic"]  # no truth: no check columns
    for row in rows:
        assert row["truth"] == "false" and row["accuracy"] == "" and row["checks_passed"] == "" and row["leak"] == ""
        assert 0 < number(row["walls_kept"]) <= 1 and number(row["leak_vs_standard"]) >= number(row["far_leak"]) >= 0
        if row["mode"] == "standard":  # against itself
            assert (number(row["walls_kept"]), number(row["leak_vs_standard"]), number(row["far_leak"])) == (1, 0, 0)
        assert row["consistency_method"] == "arc" and 0 < number(row["consistency_endpoint_occupied"]) <= 1
        assert 0 < number(row["holdout_auc"]) <= 1 and int(row["holdout_readings"]) > 0
    no_mapping(monkeypatch)
    back = run("compare", "--from-json", tmp_path / "h.json", "--json", tmp_path / "h2.json", "--csv",
               tmp_path / "h2.csv", "--require", "em.holdout_loglik > -100", "-q")
    assert back.exit_code == 0, back.output
    assert "Held-out AUC" in back.output and "Ends on occ." in back.output and "Walls kept" in back.output
    assert without_provenance(json.loads((tmp_path / "h2.json").read_text())) == without_provenance(
        json.loads((tmp_path / "h.json").read_text()))
    assert (tmp_path / "h2.csv").read_bytes() == (tmp_path / "h.csv").read_bytes()


def test_results_in_two_files_or_of_two_splits_exit_2_naming_both(runs, tmp_path):
    out, _ = runs
    shutil.copy(out / "a.json", tmp_path / "copy.json")
    twice = run("compare", "--from-json", out / "a.json", tmp_path / "copy.json", "-q")
    assert twice.exit_code == 2 and "Traceback" not in twice.output
    assert f"{tmp_path / 'copy.json'}: results[0]:" in twice.output and f"{out / 'a.json'} results[0]" in twice.output
    doc = json.loads((out / "b.json").read_text())
    doc["holdout"] = {"fraction": 0.1, "seed": 0, "reference": {"auc": {}}}
    for r in doc["results"]:
        r["metrics"].update(holdout_auc=0.7, holdout_auc_band=0.8, holdout_loglik=1.0, holdout_readings=12,
                            holdout_scans=1)
    (tmp_path / "split.json").write_text(json.dumps(doc))
    split = run("compare", "--from-json", out / "a.json", tmp_path / "split.json", "-q")
    assert split.exit_code == 2
    assert "split.json: holdout: held-out scores of --holdout 0.1 --seed 0, but" in split.output
    assert "a.json has no held-out scores" in split.output


def broken(doc, case):
    """A copy of ``doc`` damaged as ``case`` says: (the document, the key the error names)."""
    doc = json.loads(json.dumps(doc))
    if case == "list":
        return doc["results"], None
    if case == "format_version":
        doc["format_version"] = 2
    elif case == "format":
        del doc["format"]
    elif case == "results":
        doc["results"] = []
    elif case == "mode":
        del doc["results"][1]["mode"]
        return doc, "results[1].mode"
    elif case == "accuracy":
        doc["results"][0]["metrics"]["accuracy"] = "high"
        return doc, "results[0].metrics.accuracy"
    elif case == "passed":
        doc["results"][1]["metrics"]["checks"][0]["passed"] = "yes"
        return doc, "results[1].metrics.checks[0].passed"
    elif case == "truth":
        doc["results"][0]["truth"] = False
        return doc, "results[0].consistency"
    return doc, case


@pytest.mark.parametrize("case", ["list", "format_version", "format", "results", "mode", "accuracy", "passed", "truth"])
def test_a_bad_results_file_exits_2_naming_the_file_and_the_key(runs, tmp_path, case):
    out, _ = runs
    doc, key = broken(json.loads((out / "a.json").read_text()), case)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    result = run("compare", "--from-json", out / "b.json", path, "--json", tmp_path / "r.json", "-q")
    assert result.exit_code == 2, result.output
    assert f"{path}: {key}: " in result.output if key else f"{path}: expected a JSON object" in result.output
    assert "Traceback" not in result.output and not (tmp_path / "r.json").exists()


def test_a_file_that_is_not_json_exits_2(logs, runs, tmp_path):
    out, _ = runs
    (tmp_path / "half.json").write_text(json.dumps({"format": "aogm-compare"})[:-3])
    for path, words in ((tmp_path / "half.json", "not JSON (Unterminated string"), (logs[0], "not JSON (not UTF-8"),
                        (tmp_path / "nowhere.json", "no such file")):
        result = run("compare", "--from-json", path, "-q")
        assert result.exit_code == 2 and f"{path}: {words}" in result.output, result.output


@pytest.mark.parametrize("args, option", [
    (["--figure", "f.png"], "--figure"), (["--maps-dir", "maps"], "--maps-dir"), (["--holdout", "0.1"], "--holdout"),
    (["--modes", "em"], "--modes"), (["--csv", "a.json"], "--csv"), (["--require", "adaptive.accuracy > 0"], "adaptive"),
    (["--require", "em.holdout_auc > 0"], "--holdout"),
])
def test_from_json_refuses_what_needs_maps_and_bad_options(runs, monkeypatch, args, option):
    out, _ = runs
    monkeypatch.chdir(out)
    result = run("compare", "--from-json", "a.json", *args, "-q")
    assert result.exit_code == 2 and option in result.output and "Traceback" not in result.output, result.output
    assert not (out / "f.png").exists() and not (out / "maps").exists()

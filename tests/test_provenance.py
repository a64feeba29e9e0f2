"""Provenance in every output file (the ``provenance`` root attribute) and ``aogm info``."""

import hashlib
import json
import re
import subprocess
import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from numpy.testing import assert_array_equal

from aogm_cli import __version__
from aogm_cli.cli import main
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.io.provenance import LIBRARIES, git_commit, provenance

WORLDS = Path(__file__).resolve().parents[1] / "worlds"
ROOT = Path(__file__).resolve().parents[1]


def run(*args):
    """``aogm ARGS`` in this process, with ``sys.argv`` as the console script would see it."""
    argv = ["aogm", *map(str, args)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sys, "argv", argv)
        return CliRunner().invoke(main, argv[1:])


def sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def recorded(path) -> dict:
    with h5py.File(path, "r") as f:
        return json.loads(f.attrs["provenance"])


@pytest.fixture(scope="module")
def files(tmp_path_factory, corridor_door_log):
    """The corridor log simulated in process (``aogm simulate WORLD -o LOG --seed 1 -q``, conftest.py)
    and its standard map (``python -m aogm_cli``)."""
    folder = tmp_path_factory.mktemp("prov")
    log, m = corridor_door_log, folder / "door_map.h5"
    done = subprocess.run([sys.executable, "-m", "aogm_cli", "map", str(log), "--mode", "standard", "-o", str(m), "-q"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    return folder, log, m


def test_map_provenance_names_the_log_sha256_the_command_and_versions(files):
    _, log, m = files
    p = recorded(m)
    assert p["inputs"] == [{"path": str(log), "sha256": sha256(log)}]
    assert p["command"][1:] == ["map", str(log), "--mode", "standard", "-o", str(m), "-q"]  # sys.argv as run
    assert p["aogm_version"] == __version__
    assert set(p["libraries"]) == set(LIBRARIES)
    assert p["libraries"]["numpy"] == np.__version__ and p["libraries"]["h5py"] == h5py.__version__
    assert p["python"] == ".".join(map(str, sys.version_info[:3])) and p["platform"]
    when = datetime.fromisoformat(p["time"])
    assert when.utcoffset() == timedelta(0) and abs(datetime.now(UTC) - when) < timedelta(minutes=10)
    if "git_commit" in p:  # run from a checkout
        assert re.fullmatch(r"[0-9a-f]{40}(-dirty)?", p["git_commit"])


def test_log_provenance_names_the_world_file(files):
    _, log, _ = files
    p = recorded(log)
    world = WORLDS / "corridor_door.yaml"
    assert p["inputs"] == [{"path": str(world), "sha256": sha256(world)}]
    assert p["command"] == ["aogm", "simulate", str(world), "-o", str(log), "--seed", "1", "-q"]


def test_same_seed_same_arrays_whatever_the_provenance(files, tmp_path):
    _, first, _ = files
    again = tmp_path / "again.h5"
    assert run("simulate", WORLDS / "corridor_door.yaml", "-o", again, "--seed", 1, "-q").exit_code == 0

    def contents(path):
        arrays, attrs = {}, {}
        with h5py.File(path, "r") as f:
            f.visititems(lambda name, obj: arrays.__setitem__(name, obj[...]) if isinstance(obj, h5py.Dataset) else None)
            f.visititems(lambda name, obj: attrs.__setitem__(name, dict(obj.attrs)))
            attrs["/"] = {k: v for k, v in f.attrs.items() if k != "provenance"}
        return arrays, attrs

    (a, a_attrs), (b, b_attrs) = contents(first), contents(again)
    assert a.keys() == b.keys() and len(a) >= 7
    for name in a:
        assert_array_equal(a[name], b[name], err_msg=name)  # bit for bit (NaN where NaN)
        assert a[name].dtype == b[name].dtype
    assert json.dumps(a_attrs, default=str) == json.dumps(b_attrs, default=str)
    pa, pb = recorded(first), recorded(again)
    assert {k: v for k, v in pa.items() if k not in ("time", "command")} == \
        {k: v for k, v in pb.items() if k not in ("time", "command")}  # the time (and output name) may differ


def test_git_commit_outside_a_checkout_or_without_git_is_none(tmp_path, monkeypatch):
    assert git_commit(tmp_path) is None
    monkeypatch.setenv("PATH", str(tmp_path))  # no git to run
    assert git_commit() is None
    assert "git_commit" not in provenance([])


def test_provenance_skips_absent_inputs_and_records_missing_files(tmp_path):
    (tmp_path / "a.txt").write_bytes(b"abc")
    p = provenance([tmp_path / "a.txt", None, tmp_path / "gone.txt"], argv=["aogm", "x"])
    assert p["inputs"] == [{"path": str(tmp_path / "a.txt"), "sha256": hashlib.sha256(b"abc").hexdigest()},
                           {"path": str(tmp_path / "gone.txt"), "sha256": None}]
    assert p["command"] == ["aogm", "x"]
    json.dumps(p)  # JSON as it is


def test_imported_log_names_the_imported_file_and_a_folder_its_files(tmp_path):
    data, out = tmp_path / "plain.txt", tmp_path / "plain.h5"
    data.write_text("0 0 0 1 2\n0.1 0 0 1 2\n")
    result = run("import", "text", "--ranges", data, "-o", out, "-q")
    assert result.exit_code == 0, result.output
    assert recorded(out)["inputs"] == [{"path": str(data), "sha256": sha256(data)}]
    assert recorded(out)["command"][:3] == ["aogm", "import", "text"]
    bag = tmp_path / "bag"  # a ROS 2 bag is a folder: each of its files is an input
    (bag / "sub").mkdir(parents=True)
    (bag / "metadata.yaml").write_text("m")
    (bag / "sub" / "bag_0.db3").write_bytes(b"db")
    assert provenance([bag])["inputs"] == [{"path": str(bag / "metadata.yaml"), "sha256": sha256(bag / "metadata.yaml")},
                                           {"path": str(bag / "sub" / "bag_0.db3"), "sha256": sha256(bag / "sub" / "bag_0.db3")}]


def test_info_on_a_log_and_a_map(files):
    _, log, m = files
    result = run("info", log)
    assert result.exit_code == 0, result.output
    out = result.output
    assert f"{log}: log" in out and "121 scans x 24 sensors" in out and "sonar" in out
    assert "grid: 130 x 420 cells (H x W), resolution 0.05 m, origin (-0.5, -0.5)" in out
    assert "provenance:" in out and sha256(WORLDS / "corridor_door.yaml") in out and "numpy" in out
    result = run("info", m)
    assert result.exit_code == 0, result.output
    out = result.output
    for text in (f"{m}: map", "mode: standard", "grid: 130 x 420", "runtime:", "inverse_model:", "l_occ 0.85",
                 "stats:", f"{log}  sha256 {sha256(log)}", f"aogm: {__version__}", "time: "):
        assert text in out, text
    assert "command: " in out and " map " in out.split("command: ")[1].splitlines()[0]
    summary = json.loads(run("info", m, "--json").output)
    assert summary["kind"] == "map" and summary["provenance"] == recorded(m) and summary["grid"]["shape"] == [130, 420]


def test_info_on_a_detector_and_on_a_file_without_provenance(files, tmp_path):
    folder, log, _ = files
    det = tmp_path / "det.h5"
    result = run("train", log, "-o", det, "--seed", 1, "--hidden", 4, "-q")
    assert result.exit_code == 0, result.output
    assert recorded(det)["inputs"] == [{"path": str(log), "sha256": sha256(log)}]
    result = run("info", det)
    assert result.exit_code == 0, result.output
    for text in (f"{det}: detector", "features: 20", "threshold:", "precision", "training logs:",
                 f"train: {log.name}", "provenance:", sha256(log)):
        assert text in result.output, text
    old = tmp_path / "old.h5"
    write_log(old, read_log(log))  # written without provenance, as before aogm recorded it
    result = run("info", old)
    assert result.exit_code == 0 and "provenance: none recorded" in result.output


def test_info_on_a_file_that_is_not_aogms_exits_2(tmp_path):
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "something-else"
    for path in (text, other, tmp_path / "missing.h5"):
        result = run("info", path)
        assert result.exit_code == 2 and str(path) in result.output, result.output
    assert "'something-else'" in run("info", other).output


def test_calibrate_model_file_records_provenance(files, tmp_path):
    _, log, _ = files
    out = tmp_path / "model.yaml"
    result = run("calibrate", log, "-o", out, "--max-sweeps", 2, "-q")
    assert result.exit_code == 0, result.output
    made = yaml.safe_load(out.read_text())["provenance"]
    assert made["inputs"][0] == {"path": str(log), "sha256": sha256(log)}
    result = run("map", log, "--mode", "em", "--forward-model", out, "--max-sweeps", 1, "-o", tmp_path / "m.h5", "-q")
    assert result.exit_code == 0, result.output

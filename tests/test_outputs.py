"""Every command's outputs are checked before any work (``io.outputs.resolve_outputs``): refusals
exit 2 naming the path and leave every file as it was; shared options; report.json provenance."""

import hashlib
import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli import map_files
from aogm_cli.cli import main
from aogm_cli.io import outputs
from aogm_cli.io.detectorfile import default_detector_path
from aogm_cli.mapping.params import MapParams

WORLD = """
name: tiny_room
bounds: [-0.5, -0.5, 4.5, 3.0]
truth_resolution: 0.1
walls:
  - points: [[0, 0], [4, 0], [4, 2.5], [0, 2.5], [0, 0]]
trajectory:
  waypoints: [[0.8, 1.2], [3.2, 1.2]]
  speed: 0.5
  scan_period: 0.5
sonar: {count: 12, max_range: 3.0}
"""


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A folder with a world, its log, a map of the log, a detector, a params file, text and
    CARMEN inputs, a sub-folder, and links to the world (symbolic and hard)."""
    d = tmp_path_factory.mktemp("files")
    (d / "w.yaml").write_text(WORLD)
    assert run("simulate", d / "w.yaml", "-o", d / "log.h5", "--seed", 1, "-q").exit_code == 0
    shutil.copy(d / "log.h5", d / "log2.h5")
    assert run("map", d / "log.h5", "--mode", "standard", "-o", d / "m.h5", "-q").exit_code == 0
    shutil.copy(d / "m.h5", d / "mx.pgm")  # a map file whose name is one of export's outputs
    shutil.copy(default_detector_path(), d / "det.h5")
    (d / "p.yaml").write_text("inverse_model: {l_occ: 1.0}\n")
    (d / "ranges.txt").write_text("0 0 0 1.0 2.0\n")
    (d / "poses.txt").write_text("0 0 0\n")
    (d / "robot.log").write_text("ODOM 0 0 0 0 0 0 0.0 host 0.0\n")
    (d / "sub").mkdir()
    (d / "dir.pgm").mkdir()  # export -o dir would write dir.pgm: an existing folder
    os.symlink(d / "w.yaml", d / "w_link.yaml")
    os.link(d / "w.yaml", d / "w_hard.yaml")
    return d


def snapshot(folder: Path) -> dict:
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.rglob("*")) if p.is_file()}


def assert_refused(files: Path, args, named: str, *words: str):
    """The command exits 2 with one message naming ``named``, and every file is as it was."""
    before = snapshot(files)
    result = run(*[a.replace("{}", str(files)) if isinstance(a, str) else a for a in args])
    assert result.exit_code == 2, result.output
    assert named.replace("{}", str(files)) in result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    for word in words:
        assert word in result.output
    assert snapshot(files) == before
    assert not list(files.rglob(".*.tmp"))


REFUSALS = {
    # an output that is an input (same path, a symbolic link, a hard link)
    "simulate -o world": (["simulate", "{}/w.yaml", "-o", "{}/w.yaml"], "{}/w.yaml", "is also the input"),
    "simulate -o symlink": (["simulate", "{}/w_link.yaml", "-o", "{}/w.yaml"], "{}/w.yaml", "is also the input"),
    "simulate -o hardlink": (["simulate", "{}/w.yaml", "-o", "{}/w_hard.yaml"], "{}/w_hard.yaml", "is also the input"),
    "map -o log": (["map", "{}/log.h5", "--mode", "standard", "-o", "{}/log.h5"], "{}/log.h5", "is also the input"),
    "map --png log": (["map", "{}/log.h5", "--mode", "standard", "-o", "{}/new.h5", "--png", "{}/log.h5"], "{}/log.h5",
                      "--png"),
    "map -o params": (["map", "{}/log.h5", "--mode", "standard", "--params", "{}/p.yaml", "-o", "{}/p.yaml"], "{}/p.yaml",
                      "is also the input"),
    "map -o detector": (["map", "{}/log.h5", "--mode", "adaptive", "--detector", "{}/det.h5", "-o", "{}/det.h5"],
                        "{}/det.h5", "is also the input"),
    "render -o map": (["render", "{}/m.h5", "-o", "{}/m.h5"], "{}/m.h5", "is also the input"),
    "export -o map": (["export", "{}/mx.pgm", "-o", "{}/mx"], "{}/mx.pgm", "is also the input"),
    "compare --json log": (["compare", "{}/log.h5", "--modes", "standard", "--json", "{}/log.h5"], "{}/log.h5",
                           "--json"),
    "compare --json source log": (["compare", "{}/m.h5", "--json", "{}/log.h5"], "{}/log.h5", "is also the input"),
    "compare --figure params": (["compare", "{}/log.h5", "--modes", "standard", "--params", "{}/p.yaml", "--figure",
                                 "{}/p.yaml"], "{}/p.yaml", "--figure"),
    "train -o log": (["train", "{}/log.h5", "-o", "{}/log.h5"], "{}/log.h5", "is also the input"),
    "train -o validation log": (["train", "{}/log.h5", "--validation-logs", "{}/log2.h5", "-o", "{}/log2.h5"],
                                "{}/log2.h5", "is also the input"),
    "import carmen -o log": (["import", "carmen", "{}/robot.log", "-o", "{}/robot.log"], "{}/robot.log",
                             "is also the input"),
    "import text -o ranges": (["import", "text", "--ranges", "{}/ranges.txt", "-o", "{}/ranges.txt"], "{}/ranges.txt",
                              "is also the input"),
    "import text -o poses": (["import", "text", "--ranges", "{}/ranges.txt", "--poses", "{}/poses.txt", "-o",
                              "{}/poses.txt"], "{}/poses.txt", "is also the input"),
    # two outputs of one command that are the same file
    "simulate --png = -o": (["simulate", "{}/w.yaml", "-o", "{}/x.h5", "--png", "{}/x.h5"], "{}/x.h5", "--png"),
    "map --png = -o": (["map", "{}/log.h5", "--mode", "standard", "-o", "{}/m.h5", "--png", "{}/m.h5"], "{}/m.h5",
                       "is also the output of -o"),
    "map --png = -o (new)": (["map", "{}/log.h5", "--mode", "standard", "-o", "{}/y.h5", "--png", "{}/y.h5"],
                             "{}/y.h5", "is also the output of -o"),
    "compare --figure = --json": (["compare", "{}/log.h5", "--modes", "standard", "--json", "{}/r", "--figure", "{}/r"],
                                  "{}/r", "is also the output of --json"),
    "compare --json = a --maps-dir map": (["compare", "{}/log.h5", "--modes", "standard", "--maps-dir", "{}/maps",
                                           "--json", "{}/maps/log_standard.h5"], "{}/maps/log_standard.h5",
                                          "is also the output of --json"),
    # a missing output folder
    "simulate missing folder": (["simulate", "{}/w.yaml", "-o", "{}/missing/x.h5"], "{}/missing", "does not exist"),
    "simulate --png missing folder": (["simulate", "{}/w.yaml", "-o", "{}/x.h5", "--png", "{}/missing/x.png"],
                                      "{}/missing", "does not exist"),
    "map missing folder": (["map", "{}/log.h5", "--mode", "em", "-o", "{}/missing/x.h5"], "{}/missing", "does not exist"),
    "render missing folder": (["render", "{}/m.h5", "-o", "{}/missing/x.png"], "{}/missing", "does not exist"),
    "export missing folder": (["export", "{}/m.h5", "-o", "{}/missing/x"], "{}/missing", "does not exist"),
    "compare missing folder": (["compare", "{}/log.h5", "--modes", "standard", "--json", "{}/missing/r.json"],
                               "{}/missing", "does not exist"),
    "train missing folder": (["train", "{}/log.h5", "-o", "{}/missing/d.h5"], "{}/missing", "does not exist"),
    "import carmen missing folder": (["import", "carmen", "{}/robot.log", "-o", "{}/missing/x.h5"], "{}/missing",
                                     "does not exist"),
    "import text missing folder": (["import", "text", "--ranges", "{}/ranges.txt", "-o", "{}/missing/x.h5"],
                                   "{}/missing", "does not exist"),
    # an output that is an existing folder
    "simulate -o folder": (["simulate", "{}/w.yaml", "-o", "{}/sub"], "{}/sub", "directory"),
    "map -o folder": (["map", "{}/log.h5", "--mode", "standard", "-o", "{}/sub"], "{}/sub", "directory"),
    "export -o folder": (["export", "{}/m.h5", "-o", "{}/dir"], "{}/dir.pgm", "is a folder"),
}


@pytest.fixture
def no_mapping(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("mapping started")

    monkeypatch.setattr(map_files, "map_file", fail)


@pytest.mark.parametrize("case", list(REFUSALS))
def test_refused_outputs_exit_2_and_leave_every_file(files, case, no_mapping):
    args, named, word = REFUSALS[case]
    assert_refused(files, args, named, word)


def test_a_maps_dir_map_that_is_a_folder_exits_2(files, tmp_path, no_mapping):
    (tmp_path / "maps" / "log_standard.h5").mkdir(parents=True)
    before = snapshot(files)
    result = run("compare", files / "log.h5", "--modes", "standard", "--maps-dir", tmp_path / "maps")
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{tmp_path / 'maps' / 'log_standard.h5'}: --maps-dir: is a folder" in result.output
    assert snapshot(files) == before and not list(tmp_path.rglob("*.tmp"))


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "{}/w.yaml", "-o", "{}/ro/x.h5"],
        ["map", "{}/log.h5", "--mode", "em", "-o", "{}/ro/x.h5"],
        ["render", "{}/m.h5", "-o", "{}/ro/x.png"],
        ["export", "{}/m.h5", "-o", "{}/ro/x"],
        ["compare", "{}/log.h5", "--modes", "standard", "--figure", "{}/ro/f.png"],
        ["compare", "{}/log.h5", "--modes", "standard", "--maps-dir", "{}/ro/maps"],
        ["train", "{}/log.h5", "-o", "{}/ro/d.h5"],
        ["import", "carmen", "{}/robot.log", "-o", "{}/ro/x.h5"],
        ["import", "text", "--ranges", "{}/ranges.txt", "-o", "{}/ro/x.h5"],
    ],
    ids=lambda a: " ".join(a[:2]) + (" --maps-dir" if "--maps-dir" in a else ""),
)
def test_an_output_folder_that_is_not_writable_exits_2(files, args, no_mapping, monkeypatch):
    ro = files / "ro"
    ro.mkdir(exist_ok=True)
    access = os.access
    monkeypatch.setattr(outputs.os, "access", lambda p, mode: False if Path(p) == ro else access(p, mode))
    assert_refused(files, args, "{}/ro", "not")


def test_map_to_a_missing_folder_returns_before_mapping(files, no_mapping):
    result = run("map", files / "log.h5", "--mode", "em", "-o", files / "missing" / "x.h5")
    assert result.exit_code == 2 and str(files / "missing") in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_render_and_export_take_quiet(files, tmp_path):
    result = run("render", files / "m.h5", "-o", tmp_path / "r.png", "-q")
    assert result.exit_code == 0 and result.output == ""
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
    result = run("export", files / "m.h5", "-o", tmp_path / "ros", "--quiet")
    assert result.exit_code == 0 and result.output == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.png", "ros.pgm", "ros.png", "ros.yaml", "ros_scale.yaml"]


def test_help_shows_defaults_from_the_config_dataclasses():
    text = " ".join(run("map", "--help").output.split())
    assert f"[default: {MapParams().resolution}]" in text
    assert "DETECTOR.h5|all|none" in text
    text = " ".join(run("compare", "--help").output.split())
    assert "[default: standard,em,adaptive;" in text and "[standard|em|adaptive]" in text


def _sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_report_json_has_params_and_detector_identity(files, tmp_path):
    result = run("compare", files / "log.h5", "--modes", "standard,adaptive", "--detector", files / "det.h5",
                 "--json", tmp_path / "r.json", "--maps-dir", tmp_path / "maps", "-q")
    assert result.exit_code == 0, result.output
    standard, adaptive = json.loads((tmp_path / "r.json").read_text())["results"]
    for row in (standard, adaptive):
        with h5py.File(tmp_path / "maps" / f"log_{row['mode']}.h5") as f:
            assert row["params"] == json.loads(f.attrs["params"])
    assert standard["detector"] is None
    assert adaptive["detector"] == {"path": str(files / "det.h5"), "sha256": _sha256(files / "det.h5")}
    # the map file reused: the detector its parameters record
    result = run("compare", tmp_path / "maps" / "log_adaptive.h5", "--json", tmp_path / "again.json", "-q")
    assert result.exit_code == 0, result.output
    (again,) = json.loads((tmp_path / "again.json").read_text())["results"]
    assert again["detector"] == adaptive["detector"] and again["params"] == adaptive["params"]


@pytest.mark.parametrize("detector", [None, "none"])
def test_report_json_names_the_packaged_detector_and_baselines(files, tmp_path, detector):
    extra = [] if detector is None else ["--detector", detector]
    result = run("compare", files / "log.h5", "--modes", "adaptive", *extra, "--json", tmp_path / "r.json", "-q")
    assert result.exit_code == 0, result.output
    (row,) = json.loads((tmp_path / "r.json").read_text())["results"]
    if detector is None:
        assert row["detector"] == {"path": "aogm_cli/data/detector.h5", "sha256": _sha256(default_detector_path())}
        assert row["params"]["detector"] == "packaged"
    else:
        assert row["detector"] == {"path": "none", "sha256": None}


@pytest.mark.parametrize("target", ["plan.yaml", "plan.pgm"])
def test_simulate_refuses_to_write_over_a_floorplan(tmp_path, target):
    from PIL import Image

    Image.fromarray(np.full((4, 4), 254, np.uint8)).save(tmp_path / "plan.pgm")
    (tmp_path / "plan.yaml").write_text("image: plan.pgm\nresolution: 0.5\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
                                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    (tmp_path / "w.yaml").write_text("bounds: [0, 0, 2, 2]\nfloorplan: {map: plan.yaml}\n"
                                     "trajectory: {poses: [[1.0, 1.0, 0]]}\n")
    assert_refused(tmp_path, ["simulate", str(tmp_path / "w.yaml"), "-o", str(tmp_path / target)], str(tmp_path / target),
                   "is also the input")

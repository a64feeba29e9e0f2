"""Issue 12, the input half: every bad log, map, detector or params file is exit 2 with one line
naming the file and the key, in every command and mode that reads it; no traceback, no output
file, the input unchanged; every valid input still maps (exit 0)."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import shutil
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec, Truth
from aogm_cli.io.detectorfile import default_detector_path
from aogm_cli.io.logfile import write_log

MODES = ("standard", "em", "adaptive")


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def tiny_log() -> Log:
    """A 2 m square room seen by a ring of 8 sonars from 6 poses near its centre."""
    res, n = 0.05, 40
    occupancy = np.zeros((n, n), dtype=np.uint8)
    occupancy[[0, -1], :] = 1
    occupancy[:, [0, -1]] = 1
    mount = np.array([[0.1 * math.cos(a), 0.1 * math.sin(a), a] for a in np.linspace(0, 2 * math.pi, 8, endpoint=False)])
    pose = np.array([[1.0 + 0.05 * k, 1.0, 0.1 * k] for k in range(6)])
    ranges = np.full((6, 8), 0.85, dtype=np.float32)
    ranges[2, 3] = np.inf
    ranges[4, 1] = np.nan
    cause = np.zeros((6, 8), dtype=np.int8)
    cause[2, 3] = 1
    checks = ({"name": "centre", "passable": {"from": [0.9, 1.0], "to": [1.1, 1.0], "robot_radius": 0.05}},)
    ideal = np.where(np.isnan(ranges), 0.85, ranges).astype(np.float32)
    truth = Truth(GridSpec(0.0, 0.0, res, n, n), occupancy, cause, ideal, world="name: tiny\n", checks=checks)
    return Log(np.arange(6.0), pose, ranges, SensorSpec(mount=mount), source="test", truth=truth, seed=1)


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """A valid log, its standard and adaptive maps, and a valid detector (the packaged one)."""
    folder = tmp_path_factory.mktemp("good")
    log = folder / "log.h5"
    write_log(log, tiny_log())
    for mode in ("standard", "adaptive"):
        result = run("map", log, "--mode", mode, "-o", folder / f"map_{mode}.h5", "-q")
        assert result.exit_code == 0, result.output
    shutil.copy(default_detector_path(), folder / "detector.h5")
    return folder


def bad_copy(good: Path, name: str, tmp_path: Path, edit=None) -> Path:
    """A copy of ``good/name`` in ``tmp_path``, edited by ``edit(f)`` in h5py "a" mode (its seal then
    no longer matches, so the reader walks its headers first)."""
    path = tmp_path / f"bad_{name}"
    shutil.copy(good / name, path)
    if edit is not None:
        with h5py.File(path, "a") as f:
            edit(f)
    return path


def replace(name, data):
    def edit(f):
        del f[name]
        f.create_dataset(name, data=data)

    return edit


def set_attr(obj, key, value):
    def edit(f):
        f[obj].attrs[key] = value

    return edit


def del_attr(obj, key):
    def edit(f):
        del f[obj].attrs[key]

    return edit


def assert_refused(result, file: Path, key: str | None, outputs=()):
    text = result.output
    assert result.exit_code == 2, text
    assert "Traceback" not in text and "failed:" not in text, text
    assert str(file) in text, text
    if key is not None:
        assert key in text, text
    errors = [line for line in text.splitlines() if line.startswith("aogm: error:")]
    assert len(errors) == 1, text
    for out in outputs:
        assert not Path(out).exists(), out


# (id, edit of the log, key the message names)
BAD_LOGS = [
    ("max_range_0", set_attr("sensors", "max_range", 0.0), "/sensors.max_range"),
    ("max_below_min", set_attr("sensors", "max_range", 0.1), "/sensors.max_range"),
    ("max_range_inf", set_attr("sensors", "max_range", np.inf), "/sensors.max_range"),
    ("min_range_negative", set_attr("sensors", "min_range", -0.1), "/sensors.min_range"),
    ("beam_width_0", set_attr("sensors", "beam_width", 0.0), "/sensors.beam_width"),
    ("beam_width_negative", set_attr("sensors", "beam_width", -0.5), "/sensors.beam_width"),
    ("beam_width_pi", set_attr("sensors", "beam_width", math.pi), "/sensors.beam_width"),
    ("noise_nan", set_attr("sensors", "noise_sigma", np.nan), "/sensors.noise_sigma"),
    ("noise_string", set_attr("sensors", "noise_sigma", "small"), "/sensors.noise_sigma"),
    ("kind_radar", set_attr("sensors", "kind", "radar"), "/sensors.kind"),
    ("kind_number", set_attr("sensors", "kind", 3), "/sensors.kind"),
    ("no_kind", del_attr("sensors", "kind"), "/sensors.kind"),
    ("mount_nan", replace("sensors/mount", np.full((8, 3), np.nan)), "/sensors/mount"),
    ("mount_shape", replace("sensors/mount", np.zeros((8, 2))), "/sensors/mount"),
    ("ranges_negative", replace("scans/ranges", np.full((6, 8), -1.0, dtype=np.float32)), "/scans/ranges"),
    ("ranges_strings", replace("scans/ranges", np.full((6, 8), b"x")), "/scans/ranges"),
    ("ranges_shape", replace("scans/ranges", np.ones((6, 7), dtype=np.float32)), "/scans/ranges"),
    ("no_time", lambda f: f.__delitem__("scans/time"), "/scans/time"),
    ("pose_shape", replace("scans/pose", np.zeros((6, 2))), "/scans/pose"),
    ("no_truth_occupancy", lambda f: f.__delitem__("truth/occupancy"), "/truth/occupancy"),
    ("occupancy_2", replace("truth/occupancy", np.full((40, 40), 2, dtype=np.uint8)), "/truth/occupancy"),
    ("occupancy_float", replace("truth/occupancy", np.zeros((40, 40))), "/truth/occupancy"),
    ("cause_7", replace("truth/cause", np.full((6, 8), 7, dtype=np.int8)), "/truth/cause"),
    ("cause_shape", replace("truth/cause", np.zeros((5, 8), dtype=np.int8)), "/truth/cause"),
    ("ideal_nan", replace("truth/ideal_range", np.full((6, 8), np.nan, dtype=np.float32)), "/truth/ideal_range"),
    ("no_ideal", lambda f: f.__delitem__("truth/ideal_range"), "/truth/ideal_range"),
    ("resolution_0", set_attr("truth", "resolution", 0.0), "/truth.resolution"),
    ("resolution_nan", set_attr("truth", "resolution", np.nan), "/truth.resolution"),
    ("no_resolution", del_attr("truth", "resolution"), "/truth.resolution"),
    ("resolution_string", set_attr("truth", "resolution", "fine"), "/truth.resolution"),
    ("origin_one", set_attr("truth", "origin", [0.0]), "/truth.origin"),
    ("origin_inf", set_attr("truth", "origin", [0.0, np.inf]), "/truth.origin"),
    ("checks_not_json", set_attr("truth", "checks", "[{"), "/truth.checks"),
    ("checks_object", set_attr("truth", "checks", "{}"), "/truth.checks"),
    ("checks_no_to", set_attr("truth", "checks", '[{"name": "a", "passable": {"from": [0, 0]}}]'), "/truth.checks[0]"),
    ("blocked_radius", set_attr("truth", "checks", '[{"name": "a", "blocked": {"from": [0, 0], "to": [1, 1], '
                                                   '"robot_radius": -1}}]'), "/truth.checks[0].blocked.robot_radius"),
    ("check_both_kinds", set_attr("truth", "checks", '[{"name": "a", "blocked": {}, "passable": {}}]'),
     "/truth.checks[0]"),
    ("seed_string", lambda f: f.attrs.__setitem__("seed", "one"), "seed"),
]


@pytest.mark.parametrize("edit,key", [c[1:] for c in BAD_LOGS], ids=[c[0] for c in BAD_LOGS])
def test_a_bad_log_is_refused_by_every_mode_and_compare(good, tmp_path, edit, key):
    log = bad_copy(good, "log.h5", tmp_path, edit)
    before = digest(log)
    for mode in MODES:
        out = tmp_path / f"{mode}.h5"
        assert_refused(run("map", log, "--mode", mode, "-o", out, "--detector", "all", "-q"), log, key, [out])
    out = tmp_path / "cmp.json"
    assert_refused(run("compare", log, "--json", out, "--detector", "all", "-q"), log, key, [out])
    assert digest(log) == before


def test_valid_inputs_still_map(good, tmp_path):
    log = bad_copy(good, "log.h5", tmp_path, set_attr("sensors", "kind", "laser"))  # edited, unsealed, valid
    for mode in MODES:
        assert run("map", log, "--mode", mode, "-o", tmp_path / f"{mode}.h5", "-q").exit_code == 0
    assert run("compare", good / "log.h5", "--json", tmp_path / "c.json", "-q").exit_code == 0
    for name in ("map_standard.h5", "map_adaptive.h5"):
        assert run("render", good / name, "-o", tmp_path / "m.png").exit_code == 0
        assert run("export", good / name, "--format", "ros", "-o", tmp_path / "ros").exit_code == 0


# (id, map file, edit, key)
BAD_MAPS = [
    ("probability_nan", "map_standard.h5", replace("map/probability", np.full((40, 40), np.nan, dtype=np.float32)),
     "/map/probability"),
    ("probability_above_1", "map_standard.h5", replace("map/probability", np.full((40, 40), 1.5, dtype=np.float32)),
     "/map/probability"),
    ("probability_3d", "map_standard.h5", replace("map/probability", np.zeros((40, 40, 1), dtype=np.float32)),
     "/map/probability"),
    ("no_observed", "map_standard.h5", lambda f: f.__delitem__("map/observed"), "/map/observed"),
    ("observed_shape", "map_standard.h5", replace("map/observed", np.zeros((40, 39), dtype=bool)), "/map/observed"),
    ("observed_float", "map_standard.h5", replace("map/observed", np.zeros((40, 40))), "/map/observed"),
    ("log_odds_shape", "map_standard.h5", replace("map/log_odds", np.zeros((3, 3), dtype=np.float32)), "/map/log_odds"),
    ("clusters_float", "map_adaptive.h5", replace("map/clusters", np.zeros((40, 40))), "/map/clusters"),
    ("occupied_shape", "map_adaptive.h5", replace("map/occupied", np.zeros((4, 40), dtype=bool)), "/map/occupied"),
    ("resolution_0", "map_standard.h5", set_attr("map", "resolution", 0.0), "/map.resolution"),
    ("resolution_nan", "map_standard.h5", set_attr("map", "resolution", np.nan), "/map.resolution"),
    ("no_origin", "map_standard.h5", del_attr("map", "origin"), "/map.origin"),
    ("params_not_json", "map_standard.h5", lambda f: f.attrs.__setitem__("params", "{oops"), "params"),
    ("params_list", "map_standard.h5", lambda f: f.attrs.__setitem__("params", "[1]"), "params"),
    ("runtime_negative", "map_standard.h5", lambda f: f.attrs.__setitem__("runtime_s", -1.0), "runtime_s"),
    ("runtime_nan", "map_standard.h5", lambda f: f.attrs.__setitem__("runtime_s", np.nan), "runtime_s"),
    ("mode_number", "map_standard.h5", lambda f: f.attrs.__setitem__("mode", 3), "mode"),
]


@pytest.mark.parametrize("name,edit,key", [c[1:] for c in BAD_MAPS], ids=[c[0] for c in BAD_MAPS])
def test_a_bad_map_is_refused_by_render_export_and_compare(good, tmp_path, name, edit, key):
    bad = bad_copy(good, name, tmp_path, edit)
    with h5py.File(bad, "a") as f:
        f.attrs["source_log"] = str(good / "log.h5")
    before = digest(bad)
    png, prefix = tmp_path / "m.png", tmp_path / "ros"
    assert_refused(run("render", bad, "-o", png), bad, key, [png])
    assert_refused(run("export", bad, "--format", "ros", "-o", prefix), bad, key,
                   [tmp_path / "ros.yaml", tmp_path / "ros.pgm", tmp_path / "ros.png"])
    mode = "adaptive" if "adaptive" in name else "standard"
    out = tmp_path / "c.json"
    assert_refused(run("compare", good / "log.h5", bad, "--modes", mode, "--json", out, "-q"), bad, key, [out])
    assert digest(bad) == before


def edit_layer(attr=None, value=None, dataset=None, data=None):
    def edit(f):
        if attr is not None:
            f["layers/0"].attrs[attr] = value
        if dataset is not None:
            del f[f"layers/0/{dataset}"]
            f.create_dataset(f"layers/0/{dataset}", data=data)

    return edit


BAD_DETECTORS = [
    ("features_not_json", lambda f: f.attrs.__setitem__("features", "{"), "features"),
    ("features_number", lambda f: f.attrs.__setitem__("features", 3), "features"),
    ("features_huge", lambda f: f.attrs.__setitem__(
        "features", '{"ring_neighbours": 1000000000, "time_neighbours": 1, "differences": true, "missing_flags": true}'),
     "features.ring_neighbours"),
    ("threshold_string", lambda f: f.attrs.__setitem__("threshold", "half"), "threshold"),
    ("threshold_nan", lambda f: f.attrs.__setitem__("threshold", np.nan), "threshold"),
    ("metrics_list", lambda f: f.attrs.__setitem__("metrics", "[]"), "metrics"),
    ("activation_number", edit_layer("activation", 5), "/layers/0.activation"),
    ("weight_strings", edit_layer(dataset="weight", data=np.full((3, 3), b"w")), "/layers/0/weight"),
    ("bias_nan", None, "/layers/0"),
    ("no_layers", lambda f: f.__delitem__("layers"), "/layers"),
]


def _bias_nan(f):
    bias = f["layers/0/bias"][...]
    bias[0] = np.nan
    f["layers/0/bias"][...] = bias


@pytest.mark.parametrize("edit,key", [c[1:] for c in BAD_DETECTORS], ids=[c[0] for c in BAD_DETECTORS])
def test_a_bad_detector_is_refused(good, tmp_path, edit, key):
    bad = bad_copy(good, "detector.h5", tmp_path, edit or _bias_nan)
    before = digest(bad)
    out = tmp_path / "m.h5"
    assert_refused(run("map", good / "log.h5", "--mode", "adaptive", "--detector", bad, "-o", out, "-q"), bad, key, [out])
    assert digest(bad) == before


@pytest.mark.parametrize(
    "params,key",
    [
        ("em: {max_sweeps: 2.5}", "em.max_sweeps"),
        ("em: {max_sweeps: true}", "em.max_sweeps"),
        ("em: {sigma: .nan}", "em.sigma"),
        ("em: {p_hit: high}", "em.p_hit"),
        ("inverse_model: {l_occ: .inf}", "inverse_model.l_occ"),
        ("adaptive: {near_occupied: 1}", "adaptive.near_occupied"),  # a constant, no setting
        ("adaptive: {contested: -1}", "adaptive.contested"),
        ("adaptive: {weak: .nan}", "adaptive.weak"),
        ("adaptive: {grow: 1.5}", "adaptive.grow"),
        ("resolution: .nan", "resolution"),
    ],
)
def test_bad_parameters_are_refused_alike_in_every_mode_and_compare(good, tmp_path, params, key):
    file = tmp_path / "params.yaml"
    file.write_text(params + "\n")
    for mode in MODES:
        out = tmp_path / f"{mode}.h5"
        assert_refused(run("map", good / "log.h5", "--mode", mode, "--params", file, "-o", out, "-q"), file, key, [out])
    out = tmp_path / "c.json"
    assert_refused(run("compare", good / "log.h5", "--params", file, "--json", out, "-q"), file, key, [out])


# --- byte-level damage -------------------------------------------------------------------------


def damaged(good: Path, name: str, tmp_path: Path, how: str) -> Path:
    data = bytearray((good / name).read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2]
    elif how == "cut_in_seal":  # the seal's magic, then the file ends inside its length and CRC (found by test_fuzz)
        data = data[:24]
    elif how == "zeroed":
        middle = len(data) // 2
        data[middle : middle + 300] = bytes(300)
    elif how == "zeroed_header":  # in the packaged detector: object headers the HDF5 library used to spin on
        data[2048 : 2048 + 300] = bytes(300)
    elif how == "chunk":  # flip bytes inside the first chunk of a gzip-compressed dataset
        dataset = "truth/occupancy" if name == "log.h5" else "map/probability"
        with h5py.File(good / name, "r") as f:
            info = f[dataset].id.get_chunk_info(0)
        start = info.byte_offset + info.size // 3
        data[start : start + 16] = bytes(b ^ 0xFF for b in data[start : start + 16])
    path = tmp_path / f"{how}_{name}"
    path.write_bytes(bytes(data))
    return path


def assert_not_a_crash(result, file: Path, outputs=()):
    """Exit 0 (the damage hit bytes no reader relies on) or a refusal naming the file; never exit 1."""
    assert "Traceback" not in result.output and "failed:" not in result.output, result.output
    assert result.exit_code in (0, 2), result.output
    if result.exit_code == 2:
        assert str(file) in result.output
        for out in outputs:
            assert not Path(out).exists()


@pytest.mark.parametrize("how", ["truncated", "cut_in_seal", "chunk", "zeroed"])
def test_a_damaged_log_is_refused(good, tmp_path, how):
    log = damaged(good, "log.h5", tmp_path, how)
    before = digest(log)
    for mode in MODES:
        out = tmp_path / f"{mode}.h5"
        result = run("map", log, "--mode", mode, "-o", out, "--detector", "all", "-q")
        if how == "zeroed":
            assert_not_a_crash(result, log, [out])
        else:
            assert_refused(result, log, "/truth/occupancy" if how == "chunk" else None, [out])
    assert digest(log) == before


@pytest.mark.parametrize("how", ["truncated", "cut_in_seal", "chunk", "zeroed"])
def test_a_damaged_map_is_refused(good, tmp_path, how):
    bad = damaged(good, "map_standard.h5", tmp_path, how)
    before = digest(bad)
    png = tmp_path / "m.png"
    for result in (run("render", bad, "-o", png), run("export", bad, "--format", "ros", "-o", tmp_path / "ros")):
        if how == "zeroed":
            assert_not_a_crash(result, bad, [png])
        else:
            assert_refused(result, bad, "/map/probability" if how == "chunk" else None, [png])
    assert digest(bad) == before


@pytest.mark.parametrize("how", ["truncated", "cut_in_seal", "zeroed", "zeroed_header"])
def test_a_damaged_detector_ends_soon(good, tmp_path, how, monkeypatch):
    monkeypatch.setenv("AOGM_HDF5_WATCHDOG_SECONDS", "3")  # the header walk's limit (default 20 s)
    bad = damaged(good, "detector.h5", tmp_path, how)
    out = tmp_path / "m.h5"
    t0 = time.monotonic()
    result = run("map", good / "log.h5", "--mode", "adaptive", "--detector", bad, "-o", out, "-q")
    assert time.monotonic() - t0 < 30
    if how == "zeroed":
        assert_not_a_crash(result, bad, [out])
    else:
        assert_refused(result, bad, None, [out])


# --- bad inputs named (issue 23): exit 2 naming the option, key or file ----------------------------


def assert_named(result, *names):
    """Exit 2, one line naming every one of ``names``, no traceback and no internal error."""
    text = result.output
    assert result.exit_code == 2, text
    assert "Traceback" not in text and "failed:" not in text, text
    for name in names:
        assert name in text, (name, text)


WORLD = Path(__file__).resolve().parents[1] / "worlds" / "corridor_door.yaml"


def bad_world(tmp_path, old, new) -> Path:
    path = tmp_path / "world.yaml"
    text = WORLD.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    return path


def no_truth_log(tmp_path) -> Path:
    path = tmp_path / "no_truth.h5"
    write_log(path, dataclasses.replace(tiny_log(), truth=None))
    return path


def zero_scan_log(tmp_path) -> Path:
    log = tiny_log()
    t = log.truth
    path = tmp_path / "empty.h5"
    write_log(path, dataclasses.replace(log, time=log.time[:0], pose=log.pose[:0], ranges=log.ranges[:0],
                                        truth=dataclasses.replace(t, cause=t.cause[:0], ideal_range=t.ideal_range[:0])))
    return path


def params(tmp_path, text) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(text)
    return path


def wrong_mounts(tmp_path):
    ranges, mounts = tmp_path / "lab.txt", tmp_path / "mounts.txt"
    ranges.write_text("0 0 0 1 2 3\n1 0 0 1 2 3\n")
    mounts.write_text("0.1 0 0\n0 0.1 90\n")  # two rows for three range columns
    return ["import", "text", "--ranges", ranges, "--mounts", mounts, "-o", tmp_path / "x.h5"], [str(mounts), "--mounts"]


# (id, args and the names the message must hold, from tmp_path)
BAD_INPUTS = [
    ("train_zero_scans", lambda d: (["train", zero_scan_log(d), "-o", d / "det.h5"],
                                    [str(d / "empty.h5"), "/scans", "no scans"])),
    ("simulate_seed_2_64", lambda d: (["simulate", WORLD, "--seed", str(2**64), "-o", d / "x.h5"], ["'--seed'"])),
    ("simulate_seeds_2_64", lambda d: (["simulate", WORLD, "--seeds", f"1,{2**64}", "-o", f"{d}/"], ["--seeds"])),
    *[(f"map_resolution_{v}", lambda d, v=v: (["map", no_truth_log(d), "--mode", "standard", "--resolution", v,
                                               "-o", d / "m.h5"], ["'--resolution'"]))
      for v in ("0", "nan", "inf", "-1", "1e-300")],
    ("map_grid_too_large", lambda d: (["map", no_truth_log(d), "--mode", "em", "--resolution", "0.0001",
                                       "-o", d / "m.h5"], ["--resolution: 0.0001 m is too fine", "no_truth.h5"])),
    ("calibrate_grid_too_large", lambda d: (["calibrate", no_truth_log(d), "--resolution", "0.0001"],
                                            ["--resolution: 0.0001 m is too fine"])),
    ("compare_resolution_1e-300", lambda d: (["compare", no_truth_log(d), "--modes", "standard", "--params",
                                              params(d, "resolution: 1.0e-300\n")],
                                             [str(d / "params.yaml"), "resolution: 1e-300 m is too fine"])),
    ("compare_resolution_0", lambda d: (["compare", no_truth_log(d), "--params", params(d, "resolution: 0\n")],
                                        [str(d / "params.yaml"), "resolution: expected a positive number"])),
    ("world_speed", lambda d: (["simulate", bad_world(d, "speed: 0.3", "speed: 1.0e-9"), "-o", d / "x.h5"],
                               ["world.yaml: trajectory: speed 1e-09 m/s", "3.6e+10 scans"])),
    ("world_scan_period", lambda d: (["simulate", bad_world(d, "scan_period: 0.5", "scan_period: 1.0e-7"),
                                      "-o", d / "x.h5"], ["world.yaml: trajectory: ", "scan_period 1e-07 s"])),
    ("world_sub_rays", lambda d: (["simulate", bad_world(d, "count: 24", "count: 24\n  sub_rays: 100000000"),
                                   "-o", d / "x.h5"], ["world.yaml: sonar.sub_rays: expected a whole number <= 1000"])),
    *[(f"world_truth_resolution_{v}", lambda d, v=v: (["simulate", bad_world(d, "truth_resolution: 0.05",
                                                                             f"truth_resolution: {v}"),
                                                        "-o", d / "x.h5"], ["world.yaml: truth_resolution: "]))
      for v in ("1.0e-9", "0.0002", "0", "1000")],
    ("import_text_mounts_rows", wrong_mounts),
]


@pytest.mark.parametrize("make", [c[1] for c in BAD_INPUTS], ids=[c[0] for c in BAD_INPUTS])
def test_a_bad_input_exits_2_naming_the_option_key_or_file(tmp_path, make):
    args, names = make(tmp_path)
    assert_named(run(*args), *names)

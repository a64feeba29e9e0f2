"""The cluster detector: features and labels on hand-made arrays, the detector file, ``aogm train``."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from numpy.testing import assert_allclose, assert_array_equal

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec, Truth
from aogm_cli.detector.features import FeatureSpec, features, neighbour_ranges
from aogm_cli.detector.network import Detector, Layer
from aogm_cli.io.detectorfile import TRAINING_LOGS, default_detector_path, load_detector, save_detector
from aogm_cli.io.logfile import LogReader, read_log, write_log
from aogm_cli.mapping.cluster import near_occupied
from aogm_cli.mapping.standard import truth_grid_map
from aogm_cli.sensor_models.readings import cone_bands, readings_of
from aogm_cli.sensor_models.readings import cone_templates as standard_templates
from aogm_cli.simulation.sonar import simulate
from aogm_cli.training.fit import (
    Dataset,
    TrainingConfig,
    choose_threshold,
    fit_mlp,
    layers_of,
    scores,
    split_by_world,
)
from aogm_cli.training.labels import LabelDefinition, depth_edge, erroneous, labels, standard_wrong, sub_ray_depths
from aogm_cli.training.provenance import log_provenance
from aogm_cli.world.loader import parse_world

INF, NAN = np.inf, np.nan


# ---------------------------------------------------------------- features


def test_features_wrap_the_ring_clip_time_and_normalise():
    ranges = np.array([[1.0, 2.0, INF, 4.0], [NAN, 3.0, 0.5, 6.0]], dtype=np.float32)
    spec = FeatureSpec(ring_neighbours=1, time_neighbours=1, differences=True, missing_flags=True)
    assert spec.r == 5
    assert spec.names()[:5] == ["ring-1", "ring+0", "ring+1", "time-1", "time+1"]
    x = features(ranges, 5.0, spec)
    assert x.shape == (8, 5 + 4 + 5) and x.dtype == np.float32
    # reading (t=0, j=0): ring neighbours j=3 (wraps) and j=1; time t-1 clipped to t=0, t+1 is NaN
    assert_allclose(x[0, :5], [0.8, 0.2, 0.4, 0.2, 1.0], atol=1e-7)
    assert_allclose(x[0, 5:9], [0.6, 0.2, 0.0, 0.8], atol=1e-7)  # neighbour minus centre
    assert_array_equal(x[0, 9:], [0, 0, 0, 0, 1])  # only the NaN at (t=1, j=0) is missing
    # reading (t=1, j=3): 6 m > max_range clips to 1.0 but is not missing; ring+1 wraps to j=0 (NaN)
    row = 1 * 4 + 3
    assert_allclose(x[row, :5], [0.1, 1.0, 1.0, 0.8, 1.0], atol=1e-7)
    assert_array_equal(x[row, 9:], [0, 0, 1, 0, 0])
    # reading (t=0, j=2) is the +inf: 1.0 and flagged missing (also as its own clipped t-1)
    assert_allclose(x[2, :5], [0.4, 1.0, 0.8, 1.0, 0.1], atol=1e-7)
    assert_array_equal(x[2, 9:], [0, 1, 0, 1, 0])


def test_feature_options_change_the_columns():
    ranges = np.arange(1, 13, dtype=np.float32).reshape(3, 4)
    plain = features(ranges, 12.0, FeatureSpec(0, 0, differences=False, missing_flags=False))
    assert_allclose(plain[:, 0], ranges.ravel() / 12.0, atol=1e-7)
    wide = FeatureSpec(2, 2, differences=False, missing_flags=False)
    raw = neighbour_ranges(ranges, wide)
    assert raw.shape == (3, 4, 9)
    assert_array_equal(raw[0, 0], [3, 4, 1, 2, 3, 1, 1, 5, 9])  # ring j-2..j+2 wrapped; t-2, t-1 clipped; t+1, t+2
    assert features(ranges, 12.0, wide).shape == (12, 9)


def test_feature_spec_json_round_trip_and_errors():
    spec = FeatureSpec(3, 0, differences=False, missing_flags=True)
    text = spec.to_json()
    assert json.loads(text)["R"] == 7
    assert FeatureSpec.from_json(text) == spec
    with pytest.raises(InputError) as err:
        FeatureSpec.from_json('{"ring_neighbours": 1}', file="d.h5")
    assert err.value.file == "d.h5" and err.value.key == "features.time_neighbours"
    with pytest.raises(InputError) as err:
        FeatureSpec.from_json('{"ring_neighbours": -1, "time_neighbours": 0, "differences": true, "missing_flags": true}', file="d.h5")
    assert err.value.key == "features.ring_neighbours" and err.value.file == "d.h5"
    with pytest.raises(InputError, match="JSON"):
        FeatureSpec.from_json("not json", file="d.h5")


# ---------------------------------------------------------------- labels


def test_erroneous_readings_from_causes_and_ranges():
    ranges = np.array([[1.05, INF, 0.5, 3.0], [1.5, 1.0, INF, 2.0]], dtype=np.float32)
    cause = np.array([[0, 1, 2, 3], [0, 0, 1, 0]], dtype=np.int8)
    ideal = np.array([[1.0, INF, 2.0, 1.0], [1.0, 1.0, 2.0, INF]], dtype=np.float32)
    got = erroneous(ranges, cause, ideal, tolerance=0.3)
    # (0,0) echo within tolerance; (0,1) no echo and nothing in range: correct; random; specular;
    # (1,0) 0.5 m off; (1,1) exact; (1,2) no echo though a surface is at 2 m; (1,3) echo where none can be
    assert_array_equal(got, [[False, False, True, True], [True, False, True, True]])


def test_depth_edge_needs_a_jump_near_the_sensor():
    d = np.array(
        [
            [1.0, 1.0, 1.0, 3.0, 3.0],  # door frame at 1 m, through the door at 3 m: edge
            [1.0, 1.1, 1.2, 1.3, 1.4],  # an oblique wall: gradual, no edge
            [3.0, 3.0, 10.0, 10.0, 10.0],  # a jump, but its near side is beyond the reach
            [1.0, 1.0, INF, INF, INF],  # an object's side with nothing behind it
            [1.0, 1.0, 1.5, 1.5, 1.5],  # 1.5 = 1.2 * 1 + 0.3 exactly: not more than the margin
        ]
    )
    assert_array_equal(depth_edge(d, 1.2, 0.3, 2.5), [True, False, False, True, False])


def test_sub_ray_depths_walk_the_truth_grid():
    grid = GridSpec(0.0, 0.0, 0.1, 20, 20)
    occ = np.zeros(grid.shape, dtype=np.uint8)
    occ[:, 10] = 1  # a wall covering x in [1.0, 1.1)
    occ[9:11, 10] = 0  # with a 0.2 m gap at y in [0.9, 1.1)
    poses = np.array([[[0.05, 0.5, 0.0], [0.05, 1.0, 0.0], [0.05, 1.0, math.pi]]])
    d = sub_ray_depths(occ, grid, poses, beam_width=0.0, max_range=1.9, sub_rays=3)
    assert d.shape == (1, 3, 3)
    assert_allclose(d[0, 0], 0.95)  # samples every 0.05 m: the first in the wall is at x = 1.0
    assert np.all(np.isinf(d[0, 1]))  # through the gap; nothing else within 1.9 m
    assert np.all(np.isinf(d[0, 2]))  # leaving the grid counts as free
    wide = sub_ray_depths(occ, grid, poses[:, 1:2], beam_width=math.radians(40), max_range=1.9, sub_rays=3)
    assert np.isfinite(wide[0, 0, 0]) and np.isinf(wide[0, 0, 1]) and np.isfinite(wide[0, 0, 2])
    assert depth_edge(wide, 1.2, 0.3, 2.5)[0, 0]  # the gap is narrower than the cone's arc


def test_standard_wrong_compares_the_map_with_the_truth():
    p = np.array([[0.9, 0.1, 0.5], [0.6, 0.4, 0.9]])
    truth = np.array([[0, 0, 1], [1, 1, 1]], dtype=np.uint8)
    observed = np.array([[True, True, True], [True, True, False]])
    # (0,0) occupied on free; (0,1) right; (0,2) p = 0.5 is neither; (1,0) right; (1,1) free on
    # occupied; (1,2) unobserved
    assert_array_equal(standard_wrong(p, observed, truth), [[True, False, False], [False, True, False]])


def _one_sonar(grid, z):
    sensor = SensorSpec(np.zeros((1, 3)), beam_width=math.radians(30), min_range=0.0, max_range=2.0)
    pose = np.array([[0.525, 1.025, 0.0]])  # the centre of cell (row 20, col 10), facing +x
    templates = standard_templates(grid, sensor)
    rows, cols, bins, zm = readings_of(pose, np.array([[z]], np.float32), sensor, grid, templates)
    return sensor, pose, templates, rows, cols, bins, zm


def test_cone_bands_sweep_near_the_range_and_count_a_mask():
    grid = GridSpec(0.0, 0.0, 0.05, 60, 41)
    _, _, templates, rows, cols, bins, zm = _one_sonar(grid, 1.0)
    band, counts = cone_bands(grid, templates, (rows, cols, bins, zm), 0.2, 0.05, np.ones(grid.shape, bool))
    r, c = np.nonzero(band)
    d = np.hypot(r - 20, c - 10) * 0.05
    assert band.sum() == counts[0] > 0
    assert d.min() >= zm[0] - 0.2 - 1e-9 and d.max() <= zm[0] + 0.05 + 1e-9  # only the band near the range
    assert np.all(np.abs(np.arctan2(r - 20, c - 10)) <= math.radians(15) + 1e-9)  # inside the cone
    half = cone_bands(grid, templates, (rows, cols, bins, zm), 0.2, 0.05,
                      np.arange(41 * 60).reshape(grid.shape) % 2 == 0)[1]
    assert half[0] == np.count_nonzero(band.reshape(-1)[::2])
    none, zero = cone_bands(grid, templates, (rows, cols, bins, np.array([INF])), 0.2, 0.05)
    assert not none.any() and zero[0] == 0  # a max-range reading has no band


def test_near_occupied_grows_the_occupied_cells():
    lo = np.full((5, 5), -1.0)
    lo[2, 2] = 0.5
    assert near_occupied(lo, 0).sum() == 1
    assert_array_equal(near_occupied(lo, 1), np.pad(np.ones((3, 3), bool), 1))


def test_labels_flag_arcs_where_the_standard_map_is_wrong():
    grid = GridSpec(0.0, 0.0, 0.05, 60, 41)
    occupancy = np.zeros(grid.shape, np.uint8)
    occupancy[:, 30:32] = 1  # a wall across the beam at x = 1.5 m, 1 m ahead of the sensor
    sensor, pose, *_ = _one_sonar(grid, 1.0)
    ranges = np.array([[0.975], [INF]], np.float32)  # an echo of the wall; a no-echo reading
    poses = np.vstack([pose, pose + [0.0, 0.0, math.pi]])  # the second faces away, nothing in range
    truth = Truth(grid, occupancy, np.array([[0], [1]], np.int8), np.array([[0.975], [INF]], np.float32))
    log = Log(np.arange(2.0), poses, ranges, sensor, "test", truth)
    # the arc is curved, the wall straight: the arc's ends lie in front of the wall, on free
    # cells the standard map believes occupied; the reading itself is right and no edge is near
    off = labels(log, LabelDefinition(arc_wrong_min=0))
    assert_array_equal(off, [[False], [False]])
    assert_array_equal(labels(log, LabelDefinition(arc_wrong_min=1), standard_map_of=truth_grid_map), [[True], [False]])
    assert_array_equal(labels(log, LabelDefinition(arc_wrong_min=10_000), standard_map_of=truth_grid_map), [[False], [False]])
    with pytest.raises(InputError):
        LabelDefinition(arc_wrong_min=-1)


def test_labels_need_truth():
    log = Log(np.zeros(1), np.zeros((1, 3)), np.ones((1, 2), np.float32), SensorSpec(np.zeros((2, 3))), "test")
    with pytest.raises(InputError) as err:
        labels(log, file="real.h5")
    assert err.value.key == "/truth" and err.value.file == "real.h5"


def test_label_definition_is_documented():
    text = LabelDefinition().describe()
    assert "specular" in text and "0.3 m" in text and "31 sub-rays" in text
    assert LabelDefinition().as_dict()["edge_reach"] == 2.5
    with pytest.raises(InputError):
        LabelDefinition(sub_rays=1)


# ---------------------------------------------------------------- training pieces


def test_scores_and_threshold():
    y = np.array([1, 1, 0, 0, 0], bool)
    s = scores(y, np.array([1, 0, 1, 0, 0], bool))
    assert (s["precision"], s["recall"], s["f1"]) == (0.5, 0.5, 0.5)
    assert (s["n_samples"], s["n_positive"], s["n_flagged"]) == (5, 2, 2)
    assert scores(y, np.zeros(5, bool))["f1"] == 0.0
    p = np.array([0.9, 0.4, 0.35, 0.2, 0.1])
    assert choose_threshold(y, p) == pytest.approx(0.36)  # the lowest threshold that flags 0.9 and 0.4 only
    # F1 takes the extra false positive (0.5) to reach 0.3; a precision-minded beta does not
    p = np.array([0.9, 0.3, 0.5, 0.2, 0.1])
    assert choose_threshold(y, p) == pytest.approx(0.21)
    assert choose_threshold(y, p, beta=0.3) == pytest.approx(0.51)


def test_split_by_world_holds_out_whole_logs():
    assert split_by_world(["a", "b"]) == (["a"], ["b"])
    assert split_by_world(["a"]) == (["a"], [])
    assert split_by_world(list("abcdefgh")) == (list("abcdef"), ["g", "h"])
    assert split_by_world(["a", "b", "c"], ["b", "z"]) == (["a", "c"], ["b", "z"])
    with pytest.raises(InputError):
        split_by_world(["a"], ["a"])


def _small_detector(seed: int = 0) -> tuple[Detector, object, np.ndarray]:
    rng = np.random.default_rng(seed)
    spec = FeatureSpec(1, 1)
    x = rng.random((300, spec.n_features)).astype(np.float32)
    y = x[:, 1] + 0.3 * x[:, 3] > 0.7
    model = fit_mlp(Dataset(x, y, ("synthetic",)), TrainingConfig(hidden=12, seed=seed, max_iter=300))
    det = Detector(layers_of(model), spec, 0.4, {"definition": "synthetic"}, {"train": scores(y, y)}, {"seed": seed})
    return det, model, x


def test_detector_file_round_trip_matches_sklearn(tmp_path):
    det, model, x = _small_detector()
    path = tmp_path / "det.h5"
    save_detector(path, det)
    back = load_detector(path)
    assert back.feature_spec == det.feature_spec and back.threshold == 0.4
    assert back.metrics == det.metrics and back.labels == det.labels
    assert [layer.activation for layer in back.layers] == ["tanh", "logistic"]
    assert_allclose(back.predict_proba(x), model.predict_proba(x)[:, 1], atol=1e-6)
    with h5py.File(path) as f:
        assert f.attrs["format"] == "aogm-detector" and f.attrs["format_version"] == 1
        assert f["layers/0/weight"].shape == (det.feature_spec.n_features, 12)
        assert f["layers/1"].attrs["activation"] == "logistic"
        assert json.loads(f.attrs["features"])["R"] == 5
    ranges = np.array([[1.0, 2.0, INF], [0.5, 4.0, 3.0]], np.float32)
    flags = back.flag(ranges, 5.0)
    assert flags.shape == (2, 3) and flags.dtype == bool
    assert_array_equal(flags.ravel(), model.predict_proba(features(ranges, 5.0, back.feature_spec))[:, 1] >= 0.4)


def _damage(path, action):
    with h5py.File(path, "a") as f:
        action(f)


@pytest.mark.parametrize(
    "action, key",
    [
        (lambda f: f.attrs.__setitem__("format", "aogm-map"), "format"),
        (lambda f: f.attrs.__setitem__("format_version", 7), "format_version"),
        (lambda f: f.attrs.__delitem__("features"), "features"),
        (lambda f: f.attrs.__setitem__("features", "{oops"), "features"),
        (lambda f: f.attrs.__setitem__("metrics", "[1, 2]"), "metrics"),
        (lambda f: f.attrs.__delitem__("threshold"), "threshold"),
        (lambda f: f.__delitem__("layers/1/bias"), "/layers/1/bias"),
        (lambda f: f["layers/0"].attrs.__setitem__("activation", "softsign"), "/layers/0.activation"),
        (lambda f: f.__delitem__("layers"), "/layers"),
    ],
)
def test_bad_detector_file_names_the_key(tmp_path, action, key):
    det, _, _ = _small_detector()
    path = tmp_path / "det.h5"
    save_detector(path, det)
    _damage(path, action)
    with pytest.raises(InputError) as err:
        load_detector(path)
    assert err.value.file == str(path) and err.value.key == key


def test_weights_that_do_not_fit_the_features_are_refused(tmp_path):
    det, _, _ = _small_detector()
    wrong = Detector((Layer(np.zeros((3, 2)), np.zeros(2), "tanh"), det.layers[1]), det.feature_spec, 0.5)
    path = tmp_path / "det.h5"
    save_detector(path, wrong)
    with pytest.raises(InputError) as err:
        load_detector(path)
    assert err.value.key == "/layers/0/weight"


def test_missing_or_foreign_detector_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        load_detector(tmp_path / "nope.h5")
    text = tmp_path / "text.h5"
    text.write_text("hello")
    with pytest.raises(InputError) as err:
        load_detector(text)
    assert err.value.file == str(text)


def test_packaged_detector_loads_and_flags():
    assert default_detector_path().is_file(), "run `make detector`"
    det = load_detector()
    assert det.path == str(default_detector_path())
    assert det.metrics["validation"]["n_samples"] > 0 and det.metrics["train"]["n_samples"] > 0
    flags = det.flag(np.full((3, 24), 1.0, np.float32), 5.0)
    assert flags.shape == (3, 24)


# ---------------------------------------------------------------- aogm train


def _door_world(length: float, **extra):
    """A short corridor past a 1 m door into a small room: edges at the frame, random readings
    (``extra``: more top-level keys, e.g. name and errors; the YAML text goes into the log)."""
    raw = {
        "bounds": [-0.5, -0.5, 6.5, 4.0],
        "walls": [
            {"points": [[0, 0], [6, 0]]},
            {"points": [[0, 2], [6, 2]], "openings": [{"at": 3.0, "width": 1.0}]},
            {"points": [[2, 2], [2, 3.5], [4, 3.5], [4, 2]]},
        ],
        "circles": [{"center": [4.5, 0.5], "radius": 0.15}],
        "trajectory": {"waypoints": [[1.0, 1.0], [1.0 + length, 1.0]], "scan_period": 0.5},
        "sonar": {"count": 12, "random_rate": 0.05},
    } | extra
    return parse_world(raw, file="door.yaml", text=yaml.safe_dump(raw))


@pytest.fixture(scope="module")
def tiny_logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("logs")
    paths = []
    for i, length in enumerate((4.0, 3.5)):
        path = folder / f"door{i}.h5"
        write_log(path, simulate(_door_world(length), seed=i))
        paths.append(path)
    return paths


def test_train_command_writes_a_valid_detector(tiny_logs, tmp_path):
    out = tmp_path / "det.h5"
    def args(output):
        return ["train", *map(str, tiny_logs), "-o", str(output), "--seed", "3", "--hidden", "10", "--quiet"]

    result = CliRunner().invoke(main, args(out))
    assert result.exit_code == 0, result.output
    assert "precision" in result.output and "validation" in result.output
    det = load_detector(out)
    assert det.layers[0].weight.shape == (det.feature_spec.n_features, 10)
    assert det.metrics["train"]["logs"] == [str(tiny_logs[0])]  # the last log is held out
    assert det.metrics["validation"]["logs"] == [str(tiny_logs[1])]
    assert det.metrics["validation"]["n_samples"] == len(np.arange(0, 3.5 + 1e-9, 0.15)) * 12
    assert det.training["seed"] == 3 and "definition" in det.labels
    # the same seed gives the same weights
    again = tmp_path / "again.h5"
    assert CliRunner().invoke(main, args(again)).exit_code == 0
    assert_array_equal(load_detector(again).layers[0].weight, det.layers[0].weight)


def test_train_command_bad_input_exits_2_without_output(tiny_logs, tmp_path):
    bad = tmp_path / "notalog.h5"
    bad.write_text("not hdf5")
    out = tmp_path / "det.h5"
    result = CliRunner().invoke(main, ["train", str(tiny_logs[0]), str(bad), "-o", str(out), "--quiet"])
    assert result.exit_code == 2
    assert "notalog.h5" in result.output
    assert not out.exists() and not list(tmp_path.glob(".det.h5*"))
    missing_folder = CliRunner().invoke(main, ["train", str(tiny_logs[0]), "-o", str(tmp_path / "no" / "d.h5")])
    assert missing_folder.exit_code == 2


def test_train_help_documents_features_and_labels():
    result = CliRunner().invoke(main, ["train", "--help"])
    assert result.exit_code == 0
    for phrase in ("R = 7", "specular", "depth edge", "held out", "Example", "standard map", "--arc-wrong-min",
                   "training_logs", "errors:"):
        assert phrase in result.output


# ---------------------------------------------------------------- which logs it was trained on


@pytest.fixture(scope="module")
def real_log(tmp_path_factory):
    """A door log of a realistic variant: a name and an errors: section."""
    errors = {"odometry": {"translation": 0.02}, "noise_per_metre": 0.01, "crosstalk_rate": 0.02}
    path = tmp_path_factory.mktemp("real") / "door_real.h5"
    write_log(path, simulate(_door_world(3.5, name="little_door_real", errors=errors), seed=5))
    return path


def test_train_records_the_logs_and_which_are_realistic(tiny_logs, real_log, tmp_path):
    clean = tiny_logs[0]
    out = tmp_path / "det.h5"
    result = CliRunner().invoke(main, ["train", str(real_log), str(clean), "--validation-logs", str(clean), "-o", str(out),
                                       "--seed", "1", "--hidden", "6", "--quiet"])
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        recorded = json.loads(f.attrs[TRAINING_LOGS])
        assert TRAINING_LOGS not in json.loads(f.attrs["training"])  # stored once, at the root
    assert recorded == {
        "train": [{"file": "door_real.h5", "world": "little_door_real", "realistic": True,
                   "errors": ["crosstalk_rate", "noise_per_metre", "odometry"], "seed": 5,
                   "scans": read_log(real_log).n_scans, "source": "aogm simulate door.yaml"}],
        # no name: in the world, so the world file that its source names
        "validation": [{"file": "door0.h5", "world": "door", "realistic": False, "errors": [], "seed": 0,
                        "scans": read_log(clean).n_scans, "source": "aogm simulate door.yaml"}],
    }
    assert load_detector(out).training[TRAINING_LOGS] == recorded
    # a detector file written before the attribute existed still loads, and is written back without one
    with h5py.File(out, "a") as f:
        del f.attrs[TRAINING_LOGS]
    old = load_detector(out)
    assert TRAINING_LOGS not in old.training and old.training["seed"] == 1
    save_detector(tmp_path / "again.h5", old)
    with h5py.File(tmp_path / "again.h5") as f:
        assert TRAINING_LOGS not in f.attrs
    with h5py.File(out, "a") as f:
        f.attrs[TRAINING_LOGS] = "{oops"
    with pytest.raises(InputError) as err:
        load_detector(out)
    assert err.value.key == TRAINING_LOGS


def test_log_provenance_without_the_world_text():
    log = Log(np.zeros(2), np.zeros((2, 3)), np.ones((2, 4), np.float32), SensorSpec(np.zeros((4, 3))),
              "aogm simulate worlds/x_real.yaml", None, 7)
    assert log_provenance("some/dir/x.h5", log) == {"file": "x.h5", "world": "x_real", "realistic": None, "errors": [],
                                                    "seed": 7, "scans": 2, "source": "aogm simulate worlds/x_real.yaml"}


def test_the_packaged_detector_never_trained_on_a_test_world(require):
    recorded = load_detector().training.get(TRAINING_LOGS)
    if recorded is None:
        require.missing("the packaged detector predates training_logs (make detector)")
    worlds = [entry["world"] for part in ("train", "validation") for entry in recorded[part]]
    assert worlds and not [w for w in worlds if w.startswith(("corridor_door", "corridor_specular"))]


def test_flags_made_in_chunks_equal_the_whole_log_at_once():
    """The detector reads a log a few thousand scans at a time (bounded memory); each chunk
    carries the neighbouring scans its features read, so the flags do not depend on it."""
    from aogm_cli.io.detectorfile import load_detector

    detector = load_detector(None)
    rng = np.random.default_rng(3)
    ranges = rng.uniform(0.2, 6.0, size=(301, 24)).astype(np.float32)
    ranges[rng.random(ranges.shape) < 0.1] = np.inf
    whole = detector.flag(ranges, 5.0, chunk=10**9)
    for chunk in (1, 2, 7, 100, 300):
        assert np.array_equal(detector.flag(ranges, 5.0, chunk=chunk), whole)
    assert 0 < whole.sum() < whole.size


def test_train_learns_the_sensor_model_each_sensor_carries(tiny_logs, tmp_path):
    """``aogm train --sensor-models`` writes the sensor model of its training logs' sensor into the detector: one
    per sensor, each value the median of the logs' calibrations, for simulated logs."""
    from aogm_cli.io.detectorfile import load_detector
    from aogm_cli.io.modelfile import model_for

    out = tmp_path / "det.h5"
    result = CliRunner().invoke(main, ["train", *map(str, tiny_logs), "-o", str(out), "--seed", "3", "--sensor-models",
                                       "--quiet"])
    assert result.exit_code == 0, result.output
    models = load_detector(out).sensor_models
    assert len(models) == 1 and models[0]["sensor"]["simulated"] is True
    with LogReader(tiny_logs[0]) as r:
        sensor = r.sensor
    assert model_for(models, sensor, simulated=True) is models[0]
    assert model_for(models, sensor, simulated=False) is None  # a real ring with the same mounts is not the simulator's
    assert 0 < models[0]["model"]["sigma"] < 1 and models[0]["learned_from"]
    # one training log here (the other validates): its median is that log's own calibration
    from aogm_cli.map_files import map_file, resolve_params

    own = map_file(tiny_logs[0], "em", resolve_params(overrides={"calibration": {"carried": False}}))
    assert models[0]["learned_from"] == [tiny_logs[0].name]
    # the transducer's lobe goes with the model (one learned: here the whole cone, lobe_deg 0)
    assert models[0]["model"] == pytest.approx(own.learned["sensor"] | {k: own.learned[k] for k in
                                                                         ("lobe_deg", "lobe_range")})
    assert own.learned["lobe_deg"] is not None

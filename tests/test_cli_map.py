"""``aogm map``, ``render`` and ``export`` end to end on a simulated corridor."""

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.io.logfile import read_log
from aogm_cli.io.map_server import read_map_yaml
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.mapping import sweeps


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.mark.parametrize("mode", ["standard", "em"])
def test_map_file_follows_the_contract(corridor_door_log, tmp_path, mode):
    out = tmp_path / f"{mode}.h5"
    result = run("map", corridor_door_log, "--mode", mode, "-o", out, "--png", tmp_path / "m.png", "-q")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "m.png").stat().st_size > 1000
    with h5py.File(out) as f:
        assert f.attrs["format"] == "aogm-map" and f.attrs["format_version"] == 1
        assert f.attrs["mode"] == mode and f.attrs["source_log"] == str(corridor_door_log)
        assert f.attrs["runtime_s"] > 0
        params = json.loads(f.attrs["params"])
        assert params["inverse_model"]["clamp_max"] == 3.5 and "p_hit" in params["em"]
        p = f["map/probability"][...]
        obs = f["map/observed"][...]
        assert p.dtype == np.float32 and obs.dtype == bool
        assert np.all(p[~obs] == 0.5) and 0 <= p.min() and p.max() <= 1
        assert ("log_odds" in f["map"]) == (mode == "standard")
        assert ("occupied" in f["map"]) == (mode == "em")
        assert "stats" in f
    truth = read_log(corridor_door_log).truth
    m = read_map_file(out)
    assert m.grid.shape == truth.grid.shape
    metrics = evaluate(m, truth)
    assert metrics["accuracy"] > 0.75 and 0 < metrics["occupied_f1"] <= 1


def test_em_objective_never_decreases(corridor_door_log, tmp_path):
    out = tmp_path / "em.h5"
    assert run("map", corridor_door_log, "--mode", "em", "-o", out, "-q").exit_code == 0
    objective = read_map_file(out).stats["objective_per_sweep"]
    assert len(objective) >= 2
    assert all(b >= a - 1e-6 for a, b in zip(objective, objective[1:], strict=False))


def test_parameters_from_options_and_file_are_recorded(corridor_door_log, tmp_path):
    params = tmp_path / "p.yaml"
    params.write_text("inverse_model: {l_occ: 1.2, model: constant}\nem: {p_hit: 0.5}\n")
    out = tmp_path / "m.h5"
    result = run("map", corridor_door_log, "--mode", "standard", "-o", out, "--params", params, "--l-occ", 1.0, "-q")
    assert result.exit_code == 0, result.output
    recorded = read_map_file(out).params
    assert recorded["inverse_model"]["l_occ"] == 1.0  # the option wins over the file
    assert recorded["inverse_model"]["model"] == "constant" and recorded["em"]["p_hit"] == 0.5


@pytest.mark.parametrize("mode", ["em", "adaptive"])
def test_the_same_map_on_one_thread_and_on_two(corridor_door_log, tmp_path, mode, monkeypatch):
    # with bands for problems of any size, the corridor's EM problem (2904 readings, 420 columns) is
    # swept in 7 column bands (adaptive's clusters, whose readings span fewer columns: 14), those of one
    # colour at once on --threads; every array and every count is the same as on one thread
    monkeypatch.setattr(sweeps, "BAND_READINGS", 1)
    bands, sweep_bands = [], sweeps.sweep_bands
    monkeypatch.setattr(sweeps, "sweep_bands", lambda *a: bands.append(sweep_bands(*a)) or bands[-1])
    maps = []
    for threads in (1, 2):
        out = tmp_path / f"{threads}.h5"
        result = run("map", corridor_door_log, "--mode", mode, "-o", out, "--threads", threads, "-q")
        assert result.exit_code == 0, result.output
        maps.append(read_map_file(out))
    assert max(sum(len(colour) for colour in phases) for phases, _ in bands) == {"em": 7, "adaptive": 14}[mode]
    one, two = maps
    for name in ("probability", "observed", "occupied", "clusters"):
        a, b = getattr(one, name, None), getattr(two, name, None)
        assert (a is None) == (b is None) and (a is None or np.array_equal(a, b)), name
    assert one.stats["flips_per_sweep"] == two.stats["flips_per_sweep"]
    assert one.stats["objective_per_sweep"] == two.stats["objective_per_sweep"]


def test_threads_below_one_exit_2(corridor_door_log, tmp_path):
    out = tmp_path / "m.h5"
    result = run("map", corridor_door_log, "--mode", "em", "-o", out, "--threads", 0, "-q")
    assert result.exit_code == 2 and "--threads" in result.output and not out.exists()


@pytest.mark.parametrize(
    "text, key", [("inverse_model: {l_ocq: 1}\n", "inverse_model.l_ocq"), ("em: {p_hit: 2}\n", "em.p_hit"), ("[1, 2\n", "p.yaml"),
                  ("exact: {thin: 1}\n", "exact.thin"), ("exact: {bound: 7}\n", "exact.bound"),
                  # settings removed (docs/decisions/), even at their old defaults
                  ("em: {opening_deg: 0}\n", "em.opening_deg"), ("calibration: {rounds: 4}\n", "calibration.rounds"),
                  ("calibration: {tolerance: 0.02}\n", "calibration.tolerance"), ("exact: {prior: 0.1}\n", "exact.prior"),
                  ("surface: {enabled: true}\n", "surface.enabled"),
                  ("calibration: {learn: 'sigma,specular_deg'}\n", "calibration.learn"),
                  ("calibration: {learn: 'sigma,opening_deg'}\n", "calibration.learn"),
                  ("em: {heard_incidence_deg: 35}\n", "em.heard_incidence_deg"), ("em: {start: empty}\n", "em.start"),
                  ("em: {hidden: prior}\n", "em.hidden"), ("em: {window: 4}\n", "em.window"),
                  ("adaptive: {scale: mixed}\n", "adaptive.scale")]
)
def test_bad_params_exit_2_without_output(corridor_door_log, tmp_path, text, key):
    params = tmp_path / "p.yaml"
    params.write_text(text)
    out = tmp_path / "m.h5"
    result = run("map", corridor_door_log, "--mode", "standard", "-o", out, "--params", params, "-q")
    assert result.exit_code == 2 and key in result.output and "Traceback" not in result.output
    assert not out.exists()


def test_not_a_log_exits_2(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not hdf5")
    result = run("map", bad, "--mode", "standard", "-o", tmp_path / "m.h5", "-q")
    assert result.exit_code == 2 and str(bad) in result.output
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something"
    result = run("map", tmp_path / "other.h5", "--mode", "standard", "-o", tmp_path / "m.h5", "-q")
    assert result.exit_code == 2 and "format" in result.output
    assert not (tmp_path / "m.h5").exists()


def test_render_and_ros_export_round_trip(corridor_door_log, tmp_path):
    out = tmp_path / "m.h5"
    assert run("map", corridor_door_log, "--mode", "standard", "-o", out, "-q").exit_code == 0
    assert run("render", out, "-o", tmp_path / "r.png").exit_code == 0
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
    assert run("export", out, "--format", "ros", "-o", tmp_path / "ros").exit_code == 0
    m = read_map_file(out)
    back = read_map_yaml(tmp_path / "ros.yaml")
    expected = np.full(m.grid.shape, -1, dtype=np.int8)
    expected[m.observed & (m.probability > 0.65)] = 100
    expected[m.observed & (m.probability < 0.196)] = 0
    assert np.array_equal(back.data, expected)
    assert back.resolution == m.grid.resolution
    assert back.origin[:2] == pytest.approx(m.grid.origin)
    scale = read_map_yaml(tmp_path / "ros_scale.yaml")
    assert np.allclose(scale.occupancy_probability[m.observed], m.probability[m.observed], atol=1 / 255)


@pytest.mark.parametrize("mode", ["standard", "adaptive"])
def test_map_opens_its_log_twice_at_most(corridor_door_log, tmp_path, monkeypatch, mode):
    """``aogm map`` reads its log once to check its seal and hash it for provenance, and opens it
    once as HDF5: two opens, whatever the mode (it was five)."""
    import builtins

    opened = []
    real_open, real_h5 = builtins.open, h5py.File.__init__

    def counting_open(file, *args, **kwargs):
        if str(file) == str(corridor_door_log):
            opened.append("open")
        return real_open(file, *args, **kwargs)

    def counting_h5(self, name, *args, **kwargs):
        if str(name) == str(corridor_door_log):
            opened.append("h5py")
        return real_h5(self, name, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", counting_open)
    monkeypatch.setattr(h5py.File, "__init__", counting_h5)
    out = tmp_path / "m.h5"
    result = run("map", corridor_door_log, "--mode", mode, "-o", out, "-q")
    assert result.exit_code == 0, result.output
    assert sorted(opened) == ["h5py", "open"], opened
    with h5py.File(out) as f:
        record = json.loads(f.attrs["provenance"])
    from aogm_cli.io.provenance import file_sha256

    assert record["inputs"][0] == {"path": str(corridor_door_log), "sha256": file_sha256(corridor_door_log)}


def test_map_says_in_one_line_what_it_learned(corridor_door_log, tmp_path):
    """aogm map prints what the map learned from its log (the lobe, the building's rates) and where the rest of
    its model came from; --quiet keeps it quiet."""
    log = corridor_door_log
    r = CliRunner().invoke(main, ["map", str(log), "--mode", "em", "-o", str(tmp_path / "m.h5")])
    assert r.exit_code == 0, r.output
    line = [x for x in r.output.splitlines() if "learned from this log" in x]
    assert len(line) == 1 and "lobe: the whole cone" in line[0] and "p_max" in line[0]
    assert "carried by the packaged detector" in line[0]
    r = CliRunner().invoke(main, ["map", str(log), "--mode", "em", "-o", str(tmp_path / "q.h5"), "--quiet"])
    assert r.exit_code == 0 and "learned from this log" not in r.output


def test_map_says_when_the_lobe_learned_replaces_a_configured_one(corridor_door_log, tmp_path):
    """A lobe configured (em.lobe_deg) gives way to the one learned from the log (calibration.learn has lobe_deg by
    default), and the map says so and how to keep it; without lobe_deg in calibration.learn it is not learned."""
    configured = tmp_path / "lobe.yaml"
    configured.write_text("em:\n  lobe_deg: 12\n  lobe_range: 10\n")
    r = CliRunner().invoke(main, ["map", str(corridor_door_log), "--mode", "em", "-o", str(tmp_path / "m.h5"),
                                  "--params", str(configured)])
    assert r.exit_code == 0, r.output
    line = [x for x in r.output.splitlines() if "learned from this log" in x]
    assert len(line) == 1 and "in place of the configured theta0 12 deg" in line[0], r.output
    kept = tmp_path / "kept.yaml"
    kept.write_text("em:\n  lobe_deg: 12\n  lobe_range: 10\ncalibration:\n  learn: sigma,p_rand,p_hit,p_max\n")
    r = CliRunner().invoke(main, ["map", str(corridor_door_log), "--mode", "em", "-o", str(tmp_path / "k.h5"),
                                  "--params", str(kept)])
    assert r.exit_code == 0, r.output
    assert "lobe:" not in r.output and "in place of" not in r.output
    with h5py.File(tmp_path / "k.h5") as f, h5py.File(tmp_path / "m.h5") as learned:
        assert json.loads(f.attrs["learned"])["lobe_deg"] is None  # the configured lobe is the one used:
        assert not np.array_equal(f["map/probability"][...], learned["map/probability"][...])  # the log's is the cone


LOBE_LEARNED = ("warning: em.lobe_deg is learned from the log (calibration.learn lists lobe_deg); take lobe_deg out of "
                "calibration.learn to map with 12")


@pytest.mark.parametrize("command", ["map", "compare", "calibrate"])
def test_a_set_key_that_calibration_learns_or_a_carried_model_replaces_is_warned_of(corridor_door_log, tmp_path,
                                                                                  command):
    """A forward-model key set in --params (or by an option) that the map does not map with: the lobe learned from
    the log replaces a configured one, a learned sigma only starts at the one set, and the packaged detector's model
    replaces sigma, p_rand, p_hit and p_max. One warning each; none once calibration.learn omits the key or
    calibration is off. (aogm calibrate never takes a carried model, so it learns sigma from the log.)"""
    def warnings(text, *extra):
        params = tmp_path / "p.yaml"
        params.write_text(text)
        args = {"map": ("map", corridor_door_log, "--mode", "em", "-o", tmp_path / "m.h5"),
                "compare": ("compare", corridor_door_log, "--modes", "em"), "calibrate": ("calibrate", corridor_door_log)}
        result = run(*args[command], "--params", params, "-q", *extra)
        assert result.exit_code == 0, result.output
        return [line for line in result.output.splitlines() if line.startswith("warning: ")]

    assert warnings("em: {lobe_deg: 12}\n") == [LOBE_LEARNED]
    assert warnings("em: {lobe_deg: 12}\ncalibration: {learn: 'sigma,p_rand,p_hit,p_max'}\n") == []
    assert warnings("em: {lobe_range: 5}\ncalibration: {learn: 'sigma,p_rand,p_hit,p_max'}\n") == [
        "warning: em.lobe_range has no effect while em.lobe_deg is 0 (every cell of the cone hears); set em.lobe_deg too"]
    assert warnings("em: {lobe_deg: 12, lobe_range: 5}\ncalibration: {learn: 'sigma,p_rand,p_hit,p_max'}\n") == []
    sigma = warnings("em: {sigma: 0.05}\n")
    if command == "calibrate":
        assert sigma == ["warning: em.sigma is learned from the log (calibration.learn lists sigma); take sigma out of "
                         "calibration.learn to map with 0.05"]
        return
    assert sigma == ["warning: em.sigma is the sensor model's, carried by the packaged detector; set calibration.carried: "
                     "false and take sigma out of calibration.learn to map with 0.05"]
    assert warnings("em: {lobe_deg: 12, sigma: 0.05}\ncalibration: {enabled: false}\n") == []
    if command == "map":  # an option sets a key as --params does
        assert warnings("calibration: {carried: false}\n", "--p-hit", "0.8") == [
            "warning: em.p_hit is learned from the log (calibration.learn lists p_hit); take p_hit out of "
            "calibration.learn to map with 0.8"]

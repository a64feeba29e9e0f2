"""The detection lobe (``sensor_models.lobe.learn_lobe``) given back from readings of a wall made with a known
one, or the full cone, and the cones' cells it hears."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from cone_views import bin_heading

from aogm_cli.core.grid import GridSpec
from aogm_cli.sensor_models.cone_build import build_cone_templates
from aogm_cli.sensor_models.lobe import (
    LOBE_MIN_GAIN,
    LOBE_MIN_HEARD_AT_1M,
    Lobe,
    SurfaceTable,
    explained_by_lobe,
    hits_and_chances,
    learn_lobe,
    lobe_bins,
)

ROOT = Path(__file__).resolve().parents[1]
GRID = GridSpec(0.0, 0.0, 0.05, 120, 160)
WALL_ROW = 100  # a wall along the columns, 5 m up the rows


def test_lobe_bins():
    assert lobe_bins(math.radians(30.0)) == 15
    assert lobe_bins(math.radians(20.0)) == 10
    assert lobe_bins(math.radians(7.0)) == 4  # 3.5 degrees each side: four 1-degree bins


# --- the detection lobe (``learn_lobe``) ---------------------------------------------------------


def wall_readings(heard, band_rows=(12, 20, 30, 40, 50, 60), yaws=range(20, 161, 5), cols=range(20, 141, 6)):
    """Readings from cell centres ``band_rows`` rows below the wall at WALL_ROW (0.6-3 m), heading each
    of ``yaws`` (degrees, from +cols towards +rows), with the range of the nearest point of the wall's
    line of cell centres that ``heard(r, phi_deg)`` says is heard, over rays 0.1 degree apart across the
    30-degree cone (no echo: inf). (rows, cols, bins, z) as ``learn_lobe`` takes them, and the templates."""
    tpl = build_cone_templates(GRID.resolution, math.radians(30.0), 5.0)
    rows, cs, bins, zs = [], [], [], []
    phi = np.arange(-15.0, 15.0001, 0.1)
    for d in band_rows:
        for yaw in yaws:
            k = int(tpl.heading_bin(np.array([math.radians(yaw)]))[0])
            heading = float(bin_heading(tpl, k))  # the yaw the cone is drawn at
            s = np.sin(heading + np.radians(phi))
            r = np.where(s > 1e-9, d * GRID.resolution / np.maximum(s, 1e-9), np.inf)
            ok = (r <= 5.0) & heard(r, phi)
            z = float(r[ok].min()) if ok.any() else np.inf
            for c in cols:
                rows.append(WALL_ROW - d)
                cs.append(c)
                bins.append(k)
                zs.append(z)
    return tpl, (np.array(rows, np.int64), np.array(cs, np.int64), np.array(bins, np.int64), np.array(zs))


def wall():
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    occupied[WALL_ROW * GRID.width:(WALL_ROW + 1) * GRID.width] = True
    return occupied


def heard_deg(lobe, r):
    """The angle off the axis (degrees) out to which a surface met head-on at ``r`` m is heard."""
    return math.inf if lobe.full_cone else lobe.theta0_deg * math.sqrt(max(math.log(lobe.r0_m / r), 0.0))


def kuc_siegel(theta0_deg, r0):
    return lambda r, phi: np.exp(-2.0 * (phi / theta0_deg) ** 2) / r**2 >= 1.0 / r0**2


@pytest.mark.parametrize(("theta0", "r0"), [(6.0, 8.0), (8.0, 6.0), (10.0, 20.0)])
def test_a_known_lobe_is_learned_from_readings_of_a_wall(theta0, r0):
    """A wall 0.6-3 m away met at 0-70 degrees of incidence by a beam heard by Kuc & Siegel's rule: the
    learned theta0 lies within 1.5 degrees, and the angle heard at 1 and 3 m within 1.5 degrees too."""
    tpl, cones = wall_readings(kuc_siegel(theta0, r0))
    lobe = learn_lobe(tpl, GRID, cones, wall(), 5.0, 0.05)
    assert not lobe.full_cone
    assert abs(lobe.theta0_deg - theta0) <= 1.5, lobe.theta0_deg
    true = Lobe(theta0, r0, *([None] * 9))
    for r in (1.0, 3.0):
        assert abs(heard_deg(lobe, r) - heard_deg(true, r)) <= 1.5
    assert lobe.theta0_interval_deg[0] <= lobe.theta0_deg <= lobe.theta0_interval_deg[1]
    assert lobe.echoes == int(np.isfinite(cones[3]).sum()) and lobe.explained_best >= 0.85 * lobe.echoes


def test_a_beam_heard_across_the_cone_is_the_full_cone():
    tpl, cones = wall_readings(lambda r, phi: np.ones_like(r, dtype=bool))
    lobe = learn_lobe(tpl, GRID, cones, wall(), 5.0, 0.05)
    assert lobe.full_cone and lobe.theta0_deg == math.inf and lobe.r0_m == math.inf
    assert lobe.explained_cone >= 0.9 * lobe.echoes
    assert heard_deg(lobe, 4.0) == math.inf
    record = lobe.as_dict()
    assert record["theta0_deg"] is None and record["r0_m"] is None and record["full_cone"] is True
    assert json.loads(json.dumps(record)) == record


def test_a_lobe_too_narrow_for_a_sonar_is_no_candidate():
    """Readings a 2-degree lobe hears (2.9 degrees at 1 m: less than a third of the half-cone) learn no lobe that
    narrow: the cone, or a lobe hearing at least LOBE_MIN_HEARD_AT_1M of the half-cone at 1 m."""
    tpl, cones = wall_readings(kuc_siegel(2.0, 8.0))
    lobe = learn_lobe(tpl, GRID, cones, wall(), 5.0, 0.05)
    assert lobe.full_cone or heard_deg(lobe, 1.0) >= LOBE_MIN_HEARD_AT_1M * 15.0 - 1e-9


def test_a_lobe_that_explains_few_of_the_logs_echoes_keeps_the_cone():
    """The readings of a known lobe, but most of the log's echoes random (the walls explain few of them): the
    lobe explains 4% more than the cone of those it explains, yet under LOBE_MIN_GAIN of all echoes more."""
    tpl, (rows, cols, bins, z) = wall_readings(kuc_siegel(8.0, 6.0))
    learned = learn_lobe(tpl, GRID, (rows, cols, bins, z), wall(), 5.0, 0.05)
    assert not learned.full_cone
    rng = np.random.default_rng(1)
    noisy = np.where(rng.random(z.size) < 0.985, rng.uniform(0.1, 0.5, z.size), z)  # nearer than the wall: random
    lobe = learn_lobe(tpl, GRID, (rows, cols, bins, noisy), wall(), 5.0, 0.05)
    assert lobe.explained_best - lobe.explained_cone < LOBE_MIN_GAIN * lobe.echoes and lobe.full_cone


def test_a_log_without_echoes_keeps_the_cone():
    tpl, (rows, cols, bins, z) = wall_readings(lambda r, phi: np.ones_like(r, dtype=bool))
    lobe = learn_lobe(tpl, GRID, (rows, cols, bins, np.full(z.size, np.inf)), wall(), 5.0, 0.05)
    assert lobe.full_cone and lobe.echoes == 0 and lobe.counts.sum() == 0


def test_explained_by_lobe_by_hand():
    # one echo, two surfaces: on the axis at 2.0 m (bin 0) and 10.5 degrees off it at 1.8 m (bin 10). At
    # R0 = 10 m the lobe hears the second once theta0 >= 10.5 / sqrt(ln(10 / 1.8)) = 8.02 degrees, the first
    # at any theta0; at R0 = 1.9 m it never hears the first (2.0 m > R0), the second from 10.5 / sqrt(ln(1.9
    # / 1.8)) = 45.1 degrees (beyond the candidates)
    near = np.full((1, 15), np.inf)
    angle = np.full((1, 15), np.nan)
    near[0, 0], angle[0, 0] = 2.0, 0.0
    near[0, 10], angle[0, 10] = 1.8, math.radians(10.5)
    theta0 = np.radians(np.arange(1.0, 15.5, 0.5))
    log_r0 = np.log([10.0, 1.9])
    out = np.zeros((theta0.size, 2))
    explained_by_lobe(near, angle, np.array([1.8]), 0.05, theta0, log_r0, out)
    heard_far = np.degrees(theta0) >= 10.5 / math.sqrt(math.log(10.0 / 1.8))
    assert out[:, 0].tolist() == heard_far.astype(float).tolist() and not out[:, 1].any()
    out[:] = 0
    explained_by_lobe(near, angle, np.array([2.0]), 0.05, theta0, log_r0, out)
    assert out[:, 0].tolist() == (~heard_far).astype(float).tolist() and not out[:, 1].any()


def test_hits_and_chances_by_hand():
    # two echoes at 1.0 and 2.0 m; bin 0 holds walls at 1.0 (a hit) and 1.2 m (a chance in range bin 2, the
    # second echo's: it was passed); bin 1 a wall at 0.6 m of the first (a chance, no hit)
    near = np.array([[1.0, 0.6], [1.2, np.inf]])
    table = SurfaceTable(near, np.zeros_like(near), np.array([1.0, 2.0]))
    edges, counts = hits_and_chances(table, 0.05, 5.0)
    assert edges.tolist() == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0]
    assert counts[0, 0].tolist() == [0, 0, 2, 0, 0, 0, 0, 0, 0, 0] and counts[1, 0].tolist() == [0, 0, 1] + [0] * 7
    assert counts[0, 1].tolist() == [0, 1] + [0] * 8 and not counts[1, 1].any()


def test_a_learned_lobe_replaces_a_configured_one_and_the_whole_cone_undoes_it(corridor_door_log):
    """``beam_model.heard_run`` marks the cells from the whole cones each time: a lobe learned after one configured
    replaces it, and the whole cone learned leaves every cell heard."""
    import dataclasses

    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.beam_model import heard_run
    from aogm_cli.mapping.pipeline import log_grid
    from aogm_cli.sensor_models.forward_model import ForwardModelConfig
    from aogm_cli.sensor_models.heard import heard_templates
    from aogm_cli.sensor_models.readings import lay_out_readings

    with LogReader(corridor_door_log) as reader:
        log, grid = reader.read(), log_grid(reader, 0.05)
    run = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    configured = heard_run(run, ForwardModelConfig(lobe_deg=6.0, lobe_range=4.0))
    assert 0 < configured.templates.heard.sum() < configured.templates.heard.size
    learned = heard_run(configured, ForwardModelConfig(lobe_deg=10.0, lobe_range=8.0))
    assert learned.templates.lobe == (10.0, 8.0)
    assert np.array_equal(learned.templates.heard, heard_templates(run.templates, 10.0, 8.0).heard)
    whole = heard_run(learned, dataclasses.replace(ForwardModelConfig(), lobe_deg=0.0))
    assert whole.templates is run.templates and whole.templates.heard.size == 0


def _before(log_path, mode: str, stage: str):
    """The state of a ``mode`` map of the log at ``log_path`` (defaults) just before its stage ``stage``."""
    from cone_views import state_before

    from aogm_cli.io.logfile import LogReader
    from aogm_cli.map_files import resolve_params, sensor_model
    from aogm_cli.mapping.modes import resolved_params

    with LogReader(log_path) as reader:
        log = reader.read()
        given = sensor_model(mode, resolve_params(), reader, str(log_path))
    return state_before(log, mode, resolved_params(log, resolve_params()), stage, given)


def test_the_thinned_map_takes_the_lobes_exact_pass_only_when_made_with_the_same_models(corridor_door_log):
    """The exact pass the lobe's walls were thinned with (``State.exact``) is the one ``thinning`` needs when
    the model in use has not changed since (the whole cone learned, p_max fitted before) and it was made of the
    same scans: the same thinned map, bit for bit, as a pass made afresh; a pass made with another p_max is not
    taken."""
    import dataclasses

    from aogm_cli.mapping.standard import exact_pass, thin_pass

    s = _before(corridor_door_log, "adaptive", "thinning")
    assert s.exact is not None and s.exact.made_with(s.in_use, s.whole, s.readings.cuts) and s.learned.lobe_deg == 0.0
    assert not s.exact.made_with(s.in_use, dataclasses.replace(s.whole), s.readings.cuts)  # other scans: not taken
    args = (s.whole, s.grid, s.in_use, s.standard.log_odds, s.standard.observed, s.readings.cuts, s.plan.thinning)
    taken, fresh = thin_pass(*args, exact=s.exact), thin_pass(*args)
    assert all(np.array_equal(a, b) for a, b in zip(taken, fresh, strict=True))
    forward = s.in_use.em.forward
    other = dataclasses.replace(s.in_use, em=dataclasses.replace(s.in_use.em, forward=dataclasses.replace(
        forward, p_max=forward.p_max + 0.1)))
    stale = exact_pass(s.whole, s.grid, other, s.readings.cuts)
    assert not stale.made_with(s.in_use)
    again = thin_pass(*args, exact=stale)
    assert all(np.array_equal(a, b) for a, b in zip(again, fresh, strict=True))
    assert not np.array_equal(stale.log_odds, s.exact.log_odds)


def test_a_lobe_that_narrows_the_cones_fits_p_max_again_at_them(tmp_path):
    """``rates`` fits p_max at the whole cones before the lobe; a lobe that narrows them (a beam of theta0 8)
    fits it again at the cells they hear, so the map's p_max is the one its cones give; the whole cone learned
    leaves the first fit."""
    from aogm_cli.io.logfile import write_log
    from aogm_cli.mapping import stages as S
    from aogm_cli.simulation.sonar import simulate
    from aogm_cli.world.beam_pattern import with_beam_pattern
    from aogm_cli.world.loader import load_world

    world = tmp_path / "narrow.yaml"
    world.write_text(yaml.safe_dump(with_beam_pattern((ROOT / "worlds" / "corridor_door.yaml").read_text(), 8)))
    log = tmp_path / "narrow.h5"
    write_log(log, simulate(load_world(world), seed=1))
    before = _before(log, "em", "lobe")
    after = S.lobe(before)
    assert after.learned.lobe_deg > 0 and after.readings is not before.readings
    p_max = after.learned.rates["p_max"]
    assert p_max != before.learned.rates["p_max"]
    assert p_max == S.rates(before.but(readings=after.readings)).learned.rates["p_max"]
    assert after.learned.sensor.p_max == p_max

"""The adaptive mapper: standard outside clusters, EM inside, clusters from flagged readings."""

import dataclasses
import math

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.evaluation.planner import ROBOT_RADIUS, planner_metrics
from aogm_cli.io.detectorfile import load_detector, save_detector
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.map_files import map_file, resolve_params
from aogm_cli.mapping import cluster
from aogm_cli.mapping.adaptive import coupled_groups, find_clusters
from aogm_cli.mapping.cluster import label_clusters
from aogm_cli.mapping.em import em_problem, em_readings
from aogm_cli.mapping.em_kernels.likelihood import _find
from aogm_cli.mapping.view import footprint, hit_rate_curve, one_scale, pool_adjacent_violators
from aogm_cli.sensor_models.cone_build import build_cone_templates

# no beam deflected (em.specular_deg 90): adaptive's map outside the clusters is made of the same readings as the
# standard mode's map, which stays Elfes' baseline (its beams are never stopped at a surface)
UNDEFLECTED = {"em": {"specular_deg": 90}}


def detector_with_threshold(tmp_path, threshold):
    path = tmp_path / f"det_{threshold}.h5"
    save_detector(path, dataclasses.replace(load_detector(), threshold=threshold))
    return path


def test_no_flagged_reading_gives_the_standard_map(corridor_door_log, tmp_path):
    # Elfes' map outside the clusters, and no contested or weak cells either
    params = resolve_params(overrides={"adaptive": {"outside": "elfes", "contested": 0.0, "weak": 0.0}, **UNDEFLECTED})
    never = detector_with_threshold(tmp_path, 1.0)  # p(y = 1) stays below 1 on these readings
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    standard = map_file(corridor_door_log, "standard", params)
    assert adaptive.stats["clusters"] == 0 and adaptive.stats["flagged_readings"] == 0
    assert not adaptive.clusters.any()
    assert np.array_equal(adaptive.probability, standard.probability)
    assert np.array_equal(adaptive.observed, standard.observed)
    assert np.array_equal(adaptive.occupied, (standard.log_odds > 0) & standard.observed)


def test_em_changes_nothing_outside_the_clusters_but_the_scale(corridor_door_log):
    """With Elfes' map outside the clusters, the cells outside them (and the robot's footprint, cleared as EM's
    map is) keep the standard map's occupancy, each its side of 0.5 and its order: only the scale (the hit
    rates', ``view.one_scale``) moves them; EM reports the cells it cannot decide (and the standard map holds
    free) unobserved, inside the clusters only."""
    params = resolve_params(overrides={"adaptive": {"outside": "elfes"}, **UNDEFLECTED})
    adaptive = map_file(corridor_door_log, "adaptive", params)
    standard = map_file(corridor_door_log, "standard", params)
    with LogReader(corridor_door_log) as r:
        body = footprint(standard.grid, r.poses(), r.sensor)
    inside = adaptive.clusters > 0
    outside = (adaptive.clusters == 0) & ~body
    assert adaptive.stats["clusters"] > 0
    assert np.array_equal(adaptive.occupied[outside], ((standard.log_odds > 0) & standard.observed)[outside])
    assert np.array_equal(adaptive.observed[outside], standard.observed[outside])
    seen = outside & standard.observed
    ours, theirs = adaptive.probability[seen], standard.probability[seen]
    np.testing.assert_array_equal(np.sign(ours - 0.5), np.sign(theirs - 0.5))
    assert np.all(np.diff(ours[np.argsort(theirs, kind="stable")]) >= 0) and not np.array_equal(ours, theirs)
    assert np.all(standard.observed[inside])  # clusters lie in cells the standard map observed
    unseen = standard.observed & ~adaptive.observed
    assert unseen.any() and np.all(inside[unseen]) and np.all(standard.probability[unseen] <= 0.5)
    assert np.all(adaptive.observed[body]) and np.all(adaptive.probability[body] < 0.5)


def test_pool_adjacent_violators_pools_what_does_not_rise():
    pooled, starts = pool_adjacent_violators(np.array([0.1, 0.3, 0.2, 0.4]), np.ones(4))
    np.testing.assert_allclose(pooled, [0.1, 0.25, 0.4])
    assert starts.tolist() == [0, 1, 3]
    pooled, starts = pool_adjacent_violators(np.array([0.1, 0.3, 0.2, 0.2]), np.array([1.0, 3.0, 1.0, 1.0]))
    np.testing.assert_allclose(pooled, [0.1, (0.9 + 0.2 + 0.2) / 5])  # 0.3 (w 3) falls to 0.2, then to 0.2
    assert starts.tolist() == [0, 1]


def one_row():
    """One row of seven cells: two inside a cluster (EM's 0.01 and 0.9), four outside (the
    standard map's 0.12, 0.3, 0.6, 0.97) and one at 0.5; per cell, the echoes that end in it and
    that pass it on their axis."""
    probability = np.array([[0.01, 0.9, 0.12, 0.3, 0.6, 0.97, 0.5]], dtype=np.float32)
    ends = np.array([[0, 4, 0, 1, 2, 7, 0]])
    passes = np.array([[9, 5, 99, 8, 8, 2, 0]])
    inside = np.array([[True, True, False, False, False, False, False]])
    return probability, ends, passes, inside, np.ones_like(inside)


def test_hit_rate_curves_by_hand():
    probability, ends, passes, inside, observed = one_row()
    ins = hit_rate_curve(probability, ends, passes, inside)
    np.testing.assert_allclose(ins.rate, [0.5 / 10, 4.5 / 10])  # (ends + 1/2) / (reaches + 1)
    np.testing.assert_allclose(ins.low, [0.01, 0.9], rtol=1e-6)
    np.testing.assert_allclose(ins.high, [0.01, 0.9], rtol=1e-6)
    outs = hit_rate_curve(probability, ends, passes, observed & ~inside)  # 0.5: reached by no echo
    np.testing.assert_allclose(outs.rate, [0.5 / 100, 1.5 / 10, 2.5 / 11, 7.5 / 10])
    np.testing.assert_allclose(outs.mean, [0.12, 0.3, 0.6, 0.97], rtol=1e-6)
    # a rate that falls is pooled with the one before, weighted by reaches
    passes[0, 4] = 20  # 0.6: 2.5 / 23, below 0.3's 1.5 / 10
    outs = hit_rate_curve(probability, ends, passes, observed & ~inside)
    np.testing.assert_allclose(outs.rate, [0.005, (9 * 0.15 + 22 * 2.5 / 23) / 31, 0.75])
    np.testing.assert_allclose([outs.low[1], outs.high[1]], [0.3, 0.6], rtol=1e-6)


def test_one_scale_by_hand():
    """Inside pools: rate 0.05 at 0.01, rate 0.45 at 0.9. Outside: 0.12 has rate 0.005, below
    the inside's lowest: 0.01 * 0.005 / 0.05; 0.3 has 0.15, a quarter of the way from 0.05 to
    0.45: 0.01 + 0.25 * (0.9 - 0.01); 0.6 has 2.5 / 11, which would put it at 0.404, below 0.5:
    it stops at 0.501; 0.97 has 0.75, above the highest: 1 - 0.1 * 0.25 / 0.55; 0.5 stays."""
    probability, ends, passes, inside, observed = one_row()
    out = one_scale(probability, observed, inside, ends, passes)
    expected = [0.01, 0.9, 0.001, 0.01 + 0.25 * 0.89, 0.501, 1 - 0.1 * 0.25 / 0.55, 0.5]
    np.testing.assert_allclose(out[0], expected, rtol=1e-6)
    assert out.dtype == np.float32 and probability[0, 2] == np.float32(0.12)  # a copy
    # no echo reaches the inside: nothing to join by
    np.testing.assert_array_equal(one_scale(probability, observed, inside, ends * ~inside, passes * ~inside),
                                  probability)


def test_contested_cells_alone_make_clusters(corridor_door_log, tmp_path):
    """With no flagged reading, the cells whose occupied evidence alone reaches
    ``adaptive.contested`` but which the standard map holds free are still clustered."""
    never = detector_with_threshold(tmp_path, 1.0)
    params = resolve_params(overrides={"adaptive": {"weak": 0.0, "grow": 0}, **UNDEFLECTED})
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    standard = map_file(corridor_door_log, "standard", params)
    assert adaptive.stats["flagged_readings"] == 0 and adaptive.stats["clusters"] > 0
    inside = adaptive.clusters > 0
    assert np.all(standard.log_odds[inside] <= 0)


def test_weak_cells_alone_make_clusters(corridor_door_log, tmp_path):
    """With no flagged reading and no contested cell, the cells whose standard log-odds lie
    within ``adaptive.weak`` of the prior are clustered, and only they."""
    never = detector_with_threshold(tmp_path, 1.0)
    params = resolve_params(overrides={"adaptive": {"outside": "elfes", "contested": 0.0, "grow": 0}, **UNDEFLECTED})
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    standard = map_file(corridor_door_log, "standard", params)
    weak = standard.observed & (np.abs(standard.log_odds) < params.adaptive.weak)
    assert np.array_equal(adaptive.clusters > 0, weak)
    # grown by one cell (8-connected), within the observed cells
    params = resolve_params(overrides={"adaptive": {"outside": "elfes", "contested": 0.0, "grow": 1}, **UNDEFLECTED})
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    assert np.array_equal(adaptive.clusters > 0, standard.observed & cluster.grown(weak, 1))


def test_adaptive_cli_writes_clusters_and_stats(corridor_door_log, tmp_path):
    out = tmp_path / "ad.h5"
    result = CliRunner().invoke(main, ["map", str(corridor_door_log), "--mode", "adaptive", "-o", str(out), "-q",
                                       "--png", str(tmp_path / "ad.png")])
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        assert f.attrs["mode"] == "adaptive"
        for name in ("probability", "observed", "log_odds", "occupied", "clusters"):
            assert name in f["map"], name
        assert f["map/clusters"].dtype == np.int32
        for key in ("clusters", "cells_in_clusters", "phase_seconds"):
            assert key in f["stats"].attrs
    m = read_map_file(out)
    assert m.stats["clusters"] == int(m.clusters.max())
    # the runtime is the sum of the phases, each recorded, named as the em mode names its own
    phases = m.stats["phase_seconds"]
    # the sensor's model carried by the detector: the building's lobe and p_max fitted (lobe, rates), no
    # calibration; so the thinned map outside the clusters (thinning) and its free cells checked (decided)
    assert set(phases) == {"standard", "readings", "deflections", "walls", "lobe", "thinning", "detector", "clusters",
                           "index", "rates", "sweeps", "decided", "view"}
    assert m.runtime_s == pytest.approx(sum(phases.values()), rel=1e-12)
    em = read_map_file(_em_map(corridor_door_log, tmp_path))
    assert set(em.stats["phase_seconds"]) == set(phases) - {"detector", "clusters", "thinning", "decided"}
    shared = {"sweeps", "flips_per_sweep", "objective_per_sweep", "scored_per_sweep", "pairs_per_sweep",
              "candidate_cells", "em_readings", "index_entries", "scratch_bytes"}
    assert shared <= set(m.stats) and shared <= set(em.stats)  # one stats format for both modes
    assert m.stats["sweeps"] == len(m.stats["flips_per_sweep"]) >= 1


def _em_map(log, tmp_path):
    out = tmp_path / "em.h5"
    assert CliRunner().invoke(main, ["map", str(log), "--mode", "em", "-o", str(out), "-q"]).exit_code == 0
    return out


def test_bad_detector_file_exits_2(corridor_door_log, tmp_path):
    bad = tmp_path / "bad.h5"
    with h5py.File(bad, "w") as f:
        f.attrs["format"] = "aogm-detector"
    out = tmp_path / "ad.h5"
    result = CliRunner().invoke(main, ["map", str(corridor_door_log), "--mode", "adaptive", "--detector", str(bad), "-o", str(out), "-q"])
    assert result.exit_code == 2 and str(bad) in result.output
    assert not out.exists()


def test_label_clusters_is_8_connected():
    region = np.zeros((5, 6), dtype=bool)
    region[0, 0] = region[1, 1] = True  # diagonal neighbours: one cluster
    region[3, 4] = region[4, 5] = region[3, 5] = True
    labels, n = label_clusters(region)
    assert n == 2
    assert labels[0, 0] == labels[1, 1] != labels[3, 4]
    assert labels.dtype == np.int32 and labels[2, 2] == 0


def test_coupled_groups_joins_the_clusters_one_cone_holds():
    grid = GridSpec(0.0, 0.0, 0.1, 21, 41)
    tpl = build_cone_templates(grid.resolution, math.radians(10.0), 4.0)
    config = resolve_params().em
    labels = np.zeros(grid.shape, dtype=np.int64)
    labels[10, 8] = 1  # clusters 1 and 2 on the beam of a 1.5 m reading from (10, 5) along +x
    labels[10, 14] = 2
    labels[2, 10] = 3  # 3 in the cone of a reading from (2, 5) along +x only
    labels[18, 35] = 4  # 4 in no cone
    # reading 0 joins 1 and 2; without it they are two groups, as are 3 and 4
    rows, cols, z = np.array([10, 2]), np.array([5, 5]), np.array([1.5, 1.0])
    for readings, groups in (([0, 1], 3), ([1], 4)):
        cones = (rows[readings], cols[readings], tpl.heading_bin(np.zeros(len(readings))), z[readings])
        rd = em_readings(cones, tpl, grid, 4.0, config.forward)
        occupied = np.zeros(grid.height * grid.width, dtype=bool)
        problem = em_problem(rd, tpl, grid.shape, occupied, config, labels=labels.reshape(-1))
        assert problem.seen[labels.reshape(-1) == 3].all() and not problem.seen[labels.reshape(-1) == 4].any()
        assert coupled_groups(problem, 4) == groups
        root = [_find(problem.parent, k) for k in range(1, 5)]
        assert (root[0] == root[1]) == (groups == 3)
        assert len({root[1], root[2], root[3]}) == 3


def test_clusters_joined_in_different_parts_of_the_readings_share_a_root_on_any_thread_count():
    """EM's set-up runs parts of the readings on threads, each with its own union-find: clusters
    joined by readings of different parts end in one set, rooted at the least id, and every
    reading's state is the same, on one thread and on two."""
    from aogm_cli.core.budget import Limits, using
    from aogm_cli.sensor_models.readings import READING_PARTS

    grid = GridSpec(0.0, 0.0, 0.1, 21, 41)
    tpl = build_cone_templates(grid.resolution, math.radians(10.0), 4.0)
    config = resolve_params().em
    labels = np.zeros(grid.shape, dtype=np.int64)
    labels[10, 8], labels[10, 14], labels[10, 20] = 3, 1, 2  # on the beam along +x of row 10
    n = 2 * READING_PARTS
    rows, cols, z = np.full(n, 2), np.full(n, 30), np.full(n, 0.5)  # short readings far from them
    cols[0], z[0] = 5, 1.2  # the first part's first reading joins 3 and 1
    cols[-1], z[-1] = 11, 1.2  # the last part's last reading joins 1 and 2
    rows[[0, -1]] = 10
    cones = (rows, cols, tpl.heading_bin(np.zeros(n)), z)
    made = []
    for threads in (1, 2):
        with using(Limits(threads=threads)):
            rd = em_readings(cones, tpl, grid, 4.0, config.forward)
            problem = em_problem(rd, tpl, grid.shape, np.zeros(grid.height * grid.width, dtype=bool), config,
                                 labels=labels.reshape(-1))
        assert [_find(problem.parent, k) for k in (1, 2, 3)] == [1, 1, 1]
        made.append(problem)
    assert np.array_equal(made[0].readings.ints, made[1].readings.ints)
    assert np.array_equal(made[0].readings.floats, made[1].readings.floats)
    assert np.array_equal(made[0].seen, made[1].seen)


def test_readings_near_clusters_uses_the_cone_reach():
    grid = GridSpec(0.0, 0.0, 0.1, 50, 50)
    clusters = np.zeros(grid.shape, dtype=np.int32)
    clusters[40:42, 40:42] = 1
    rows, cols = np.array([5, 5, 38]), np.array([5, 5, 38])
    z = np.array([1.0, np.inf, 0.3])
    forward = resolve_params().em.forward
    near = cluster.readings_near_clusters(clusters, rows, cols, z, grid, 5.0, forward)
    assert near.tolist() == [1, 2]  # a 1 m reading from (5, 5) cannot reach row 40; 5 m can


# --- adaptive.outside: thinned (issue 36) -------------------------------------------------------


# calibrated on the log (not carried): thinning then uses the configured forward model, as the
# standard mode's exact.thin does
THINNED = {"adaptive": {"outside": "thinned", "contested": 0.1, "weak": 0.0, "grow": 0},
           "calibration": {"carried": False}, **UNDEFLECTED}


def test_thinned_outside_keeps_clusters_small_and_reports_undecided_cells_unknown(corridor_door_log):
    """With ``adaptive.outside: thinned`` the clusters hold a small share of the observed cells
    (the default blanket holds more cells than are observed), the map outside them is the thinned
    map's, and the cells no reading decided are unknown there, as EM's hidden cells are."""
    params = resolve_params(overrides=THINNED)
    adaptive = map_file(corridor_door_log, "adaptive", params)
    thinned = map_file(corridor_door_log, "standard", resolve_params(overrides={"exact": {"thin": True}}))
    assert 0 < adaptive.stats["cells_in_clusters"] < 0.2 * adaptive.stats["observed_cells"]
    assert "thinning" in adaptive.stats["phase_seconds"]
    with LogReader(corridor_door_log) as r:
        body = footprint(thinned.grid, r.poses(), r.sensor)
    outside = (adaptive.clusters == 0) & ~body
    # outside the clusters EM's binary map is adaptive's thinned map, which frees at least what the
    # standard mode's thinning frees (it thins to the exact model's prior: plan.OUTSIDE_MARGIN)
    ours = (adaptive.log_odds > 0) & adaptive.observed
    assert np.array_equal(adaptive.occupied[outside], ours[outside])
    assert not np.any(ours & ~(thinned.log_odds > 0))
    unknown = thinned.observed & ~adaptive.observed & outside
    assert unknown.any() and np.all(adaptive.log_odds[unknown] <= 0)
    elfes = map_file(corridor_door_log, "adaptive", resolve_params(overrides={"adaptive": {"outside": "elfes"}}))
    assert elfes.stats["cells_in_clusters"] > 0.5 * elfes.stats["observed_cells"]
    # a planner reaches where it does on EM's map: the free cells no reading holds free are
    # unknown, the door frame's decided cells free (the rule before, Elfes' and the exact model's
    # evidence at the cell, left the frame unknown: block 0.078 against EM's 0.056)
    em = map_file(corridor_door_log, "em", resolve_params(overrides={"calibration": {"carried": False}}))
    with LogReader(corridor_door_log) as r:
        truth, poses = r.truth(), r.poses()
    ours, theirs = (planner_metrics(m.grid, m.probability, m.observed, truth.occupancy, poses, ROBOT_RADIUS)
                    for m in (adaptive, em))
    assert ours["leak"] <= theirs["leak"] + 0.01 and ours["block"] <= theirs["block"] + 0.01, (ours, theirs)


def test_thinned_outside_clusters_the_contested_cells(corridor_door_log):
    """With no flagged reading, the thinned design's clusters are exactly the cells the thinned
    map holds free and the exact model holds occupied by ``adaptive.contested`` or more, and the
    wall layers next to them that the thinning freed."""
    from cone_views import state_before

    from aogm_cli.mapping.modes import resolved_params

    with LogReader(corridor_door_log) as r:
        log = r.read()
    params = resolved_params(log, resolve_params(overrides=THINNED))
    state = state_before(log, "adaptive", params, "detector")
    none = np.zeros(log.ranges.size, dtype=bool)
    ids, count = find_clusters(state.readings, none, state.standard, params, state.plan, log)
    sm = state.standard
    contested = sm.observed & (sm.log_odds <= 0) & (sm.evidence >= 0.1)
    # grown by one cell into the wall layers the thinning freed (Elfes' map holds them occupied)
    layers = cluster.grown(contested, 1) & sm.observed & (sm.elfes > 0) & (sm.log_odds <= 0)
    assert count > 0 and layers.any() and np.array_equal(ids > 0, contested | layers)


def test_map_evidence_is_ems_evidence_at_the_map(corridor_door_log):
    """``exact.map_evidence`` (one pass over the cones) gives each cell the evidence EM's
    scoring gives a candidate at the same binary map: log p(Z | m, occupied) - log p(Z | m, free)."""
    from cone_views import state_before

    from aogm_cli.mapping import em as E
    from aogm_cli.mapping.exact import map_evidence
    from aogm_cli.mapping.modes import resolved_params

    with LogReader(corridor_door_log) as r:
        log = r.read()
    params = resolved_params(log, resolve_params())
    state = state_before(log, "em", params, "calibration")
    config = state.in_use.em
    occ = state.occupied.copy()
    problem, candidates = E.whole_log_problems(state.readings)(config, occ, None)
    result = E.run_em(problem, occ, candidates, dataclasses.replace(config, max_sweeps=0))  # scores, flips none
    assert np.array_equal(occ, state.occupied)
    with np.errstate(divide="ignore"):
        scored = np.log(result.residual) - np.log1p(-result.residual) - config.l_prior
    evidence = map_evidence(state.readings, config.forward, occ).reshape(-1)[candidates]
    finite = np.isfinite(scored)
    assert finite.mean() > 0.99 and (evidence < -1).mean() > 0.1
    np.testing.assert_allclose(evidence[finite], scored[finite], rtol=1e-6, atol=1e-6)
    # in parts on threads: the same evidence, bit for bit, for any thread count
    from aogm_cli.core.budget import Limits, using

    with using(Limits(threads=1)):
        one = map_evidence(state.readings, config.forward, occ)
    for threads in (2, 3):
        with using(Limits(threads=threads)):
            assert np.array_equal(map_evidence(state.readings, config.forward, occ), one)


def test_residual_scale_by_hand():
    """Outside the clusters a cell takes EM's residual logistic(evidence + l_prior) on its side of
    0.5; cells not listed, and unknown ones, keep theirs."""
    from aogm_cli.mapping.view import SIDE, residual_scale

    l_prior = math.log(0.3 / 0.7)
    probability = np.array([[0.9, 0.2, 0.7, 0.3, 0.12]], dtype=np.float32)
    evidence = np.array([[3.0, -4.0, -2.0, 2.0, 1.0]])
    cells = np.array([[True, True, True, True, False]])
    out = residual_scale(probability, cells, evidence, l_prior)
    r = 1.0 / (1.0 + np.exp(-(evidence + l_prior)))
    # occupied and free with evidence to match; an occupied cell the readings want free stays just
    # above 0.5, a free one they want occupied just below
    expected = [r[0, 0], r[0, 1], 0.5 + SIDE, 0.5 - SIDE, 0.12]
    np.testing.assert_allclose(out[0], expected, rtol=1e-6)
    assert out.dtype == probability.dtype and probability[0, 2] == np.float32(0.7)


def test_auto_keeps_elfes_map_outside_where_the_model_is_learned_from_the_log(corridor_door_log, tmp_path):
    """``adaptive.outside: auto`` keeps the thinned map outside the clusters where the sensor's
    model is known before the map is made (here carried by the detector), and Elfes' map where
    EM learns it from the log (``calibration.carried: false``), exactly as ``outside: elfes``."""
    carried = map_file(corridor_door_log, "adaptive", resolve_params())
    learned = map_file(corridor_door_log, "adaptive", resolve_params(overrides={"calibration": {"carried": False}}))
    elfes = map_file(corridor_door_log, "adaptive",
                     resolve_params(overrides={"calibration": {"carried": False}, "adaptive": {"outside": "elfes"}}))
    assert carried.params["adaptive"]["outside"] == learned.params["adaptive"]["outside"] == "auto"
    assert (carried.stats["outside"], learned.stats["outside"]) == ("thinned", "elfes")  # what auto chose
    assert {"thinning", "decided"} <= set(carried.stats["phase_seconds"])
    assert not {"thinning", "decided"} & set(learned.stats["phase_seconds"])
    assert carried.stats["cells_in_clusters"] < 0.2 * carried.stats["observed_cells"]
    assert learned.stats["cells_in_clusters"] > 0.5 * learned.stats["observed_cells"]
    for name in ("probability", "observed", "occupied", "clusters"):
        assert np.array_equal(getattr(learned, name), getattr(elfes, name)), name
    # aogm map says in one line that the model was learned, and what a given one would change
    from aogm_cli.map_files import calibration_notice

    assert "adaptive keeps the thinned map outside its clusters" in calibration_notice(corridor_door_log, learned)
    assert "adaptive keeps" not in calibration_notice(corridor_door_log, elfes)  # asked for Elfes' map
    assert calibration_notice(corridor_door_log, carried) is None
    # a laser's map is never thinned: a given model would not change what is outside its clusters
    from aogm_cli.core.log import Log, SensorSpec
    from aogm_cli.io.logfile import write_log

    laser = tmp_path / "laser.h5"
    bearings = np.linspace(-1.5, 1.5, 31)
    sensor = SensorSpec(np.stack([np.zeros(31), np.zeros(31), bearings], axis=1), "laser", math.radians(0.5), 0.0,
                        4.0, 0.01)
    poses = np.stack([np.linspace(0.0, 1.0, 10), np.zeros(10), np.zeros(10)], axis=1)
    ranges = np.tile(np.float32(2.0) / np.cos(bearings).astype(np.float32), (10, 1))  # a wall 2 m ahead
    write_log(laser, Log(np.arange(10.0), poses, np.minimum(ranges, 3.9), sensor, source="test"))
    laser_map = map_file(laser, "adaptive", resolve_params(overrides={"calibration": {"carried": False},
                                                                       "resolution": 0.1}))
    assert laser_map.plan["sensor"] == "narrow beam" and laser_map.stats["outside"] == "elfes"
    notice = calibration_notice(laser, laser_map)
    assert "calibrated the sensor's model" in notice and "adaptive keeps" not in notice

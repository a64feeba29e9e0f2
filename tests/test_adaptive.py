"""The adaptive mapper: standard outside clusters, EM inside, clusters from flagged readings."""

import dataclasses
import math

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.io.detectorfile import load_detector, save_detector
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.mapping import cluster
from aogm_cli.mapping.adaptive import coupled_groups
from aogm_cli.mapping.cluster import label_clusters
from aogm_cli.mapping.em import em_problem, em_readings, find_root, footprint
from aogm_cli.mapping.modes import map_file
from aogm_cli.mapping.params import resolve_params
from aogm_cli.sensor_models.cone import build_cone_templates


def detector_with_threshold(tmp_path, threshold):
    path = tmp_path / f"det_{threshold}.h5"
    save_detector(path, dataclasses.replace(load_detector(), threshold=threshold))
    return path


def test_no_flagged_reading_gives_the_standard_map(corridor_door_log, tmp_path):
    params = resolve_params(overrides={"adaptive": {"contested": 0.0, "weak": 0.0}})  # no contested or weak cells either
    never = detector_with_threshold(tmp_path, 1.0)  # p(y = 1) stays below 1 on these readings
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    standard = map_file(corridor_door_log, "standard", params)
    assert adaptive.stats["clusters"] == 0 and adaptive.stats["flagged_readings"] == 0
    assert not adaptive.clusters.any()
    assert np.array_equal(adaptive.probability, standard.probability)
    assert np.array_equal(adaptive.observed, standard.observed)
    assert np.array_equal(adaptive.occupied, (standard.log_odds > 0) & standard.observed)


def test_em_changes_nothing_outside_the_clusters(corridor_door_log):
    params = resolve_params()
    adaptive = map_file(corridor_door_log, "adaptive", params)
    standard = map_file(corridor_door_log, "standard", params)
    # outside the clusters and the robot's footprint (cleared, as EM's map is)
    with LogReader(corridor_door_log) as r:
        body = footprint(standard.grid, r.poses(), r.sensor)
    outside = (adaptive.clusters == 0) & ~body
    assert adaptive.stats["clusters"] > 0
    assert np.array_equal(adaptive.probability[outside], standard.probability[outside])
    assert np.array_equal(adaptive.occupied[outside], ((standard.log_odds > 0) & standard.observed)[outside])
    # clusters lie in cells the standard map observed; EM reports the cells it cannot decide
    # (and the standard map holds free) unobserved
    inside = adaptive.clusters > 0
    assert np.all(standard.observed[inside])
    unseen = standard.observed & ~adaptive.observed
    assert unseen.any() and np.all(inside[unseen]) and np.all(standard.probability[unseen] <= 0.5)
    assert np.all(adaptive.observed[body]) and np.all(adaptive.probability[body] < 0.5)


def test_contested_cells_alone_make_clusters(corridor_door_log, tmp_path):
    """With no flagged reading, the cells whose occupied evidence alone reaches
    ``adaptive.contested`` but which the standard map holds free are still clustered."""
    never = detector_with_threshold(tmp_path, 1.0)
    params = resolve_params(overrides={"adaptive": {"weak": 0.0, "grow": 0}})
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    standard = map_file(corridor_door_log, "standard", params)
    assert adaptive.stats["flagged_readings"] == 0 and adaptive.stats["clusters"] > 0
    inside = adaptive.clusters > 0
    assert np.all(standard.log_odds[inside] <= 0)


def test_weak_cells_alone_make_clusters(corridor_door_log, tmp_path):
    """With no flagged reading and no contested cell, the cells whose standard log-odds lie
    within ``adaptive.weak`` of the prior are clustered, and only they."""
    never = detector_with_threshold(tmp_path, 1.0)
    params = resolve_params(overrides={"adaptive": {"contested": 0.0, "grow": 0}})
    adaptive = map_file(corridor_door_log, "adaptive", params, str(never))
    standard = map_file(corridor_door_log, "standard", params)
    weak = standard.observed & (np.abs(standard.log_odds) < params.adaptive.weak)
    assert np.array_equal(adaptive.clusters > 0, weak)
    # grown by one cell (8-connected), within the observed cells
    params = resolve_params(overrides={"adaptive": {"contested": 0.0, "grow": 1}})
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
    assert set(phases) == {"standard", "readings", "deflections", "detector", "clusters", "index", "calibration", "sweeps",
                           "view"}
    assert m.runtime_s == pytest.approx(sum(phases.values()), rel=1e-12)
    em = read_map_file(_em_map(corridor_door_log, tmp_path))
    assert set(em.stats["phase_seconds"]) == set(phases) - {"detector", "clusters"}
    shared = {"sweeps", "flips_per_sweep", "objective_per_sweep", "scored_per_sweep", "pairs_per_sweep",
              "candidate_cells", "em_readings", "index_entries", "scratch_bytes", "calibration"}
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
        root = [find_root(problem.parent, k) for k in range(1, 5)]
        assert (root[0] == root[1]) == (groups == 3)
        assert len({root[1], root[2], root[3]}) == 3


def test_readings_near_clusters_uses_the_cone_reach():
    grid = GridSpec(0.0, 0.0, 0.1, 50, 50)
    clusters = np.zeros(grid.shape, dtype=np.int32)
    clusters[40:42, 40:42] = 1
    rows, cols = np.array([5, 5, 38]), np.array([5, 5, 38])
    z = np.array([1.0, np.inf, 0.3])
    forward = resolve_params().em.forward
    near = cluster.readings_near_clusters(clusters, rows, cols, z, grid, 5.0, forward)
    assert near.tolist() == [1, 2]  # a 1 m reading from (5, 5) cannot reach row 40; 5 m can

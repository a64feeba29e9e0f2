"""What a planner sees (``evaluation.planner``): leak, block, surface_recall, walls_kept,
leak_vs_standard and far_leak on hand-made grids with hand-counted cells, and ``aogm compare`` reporting them
(table, JSON, CSV, gates, --robot-radius, --from-json of older files, logs without truth)."""

import dataclasses
import json

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.evaluation.planner import against_standard, map_reach, planner_metrics
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.report import scoring
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import parse_world

# 21 x 30 cells of 0.1 m; the truth is a 1-cell-thick wall across row 10. A robot of 0.15 m fits
# on a cell 2 cells (0.2 m) from every obstacle and the grid's edge, not on one sqrt(2) cells
# (0.141 m) away: below the wall it drives rows 1-8, columns 1-28 (224 cells), and as much above.
GRID = GridSpec(0.0, 0.0, 0.1, 21, 30)
RADIUS = 0.15
BELOW = 8 * 28
POSES = np.array([[0.55 + 0.1 * k, 0.45, 0.0] for k in range(11)])  # row 4, columns 5-15
TRUTH = np.zeros(GRID.shape, dtype=np.uint8)
TRUTH[10, :] = 1
OBSERVED = np.ones(GRID.shape, dtype=bool)


def wall_map(gap: tuple[int, int] | None = None, p_wall: float = 0.9) -> np.ndarray:
    """Probabilities: the truth's wall at ``p_wall``, free 0.1, with columns gap[0]:gap[1] of the wall free."""
    p = np.full(GRID.shape, 0.1)
    p[10, :] = p_wall
    if gap is not None:
        p[10, gap[0]:gap[1]] = 0.1
    return p


def metrics(p, observed=OBSERVED, radius=RADIUS):
    return planner_metrics(GRID, p, observed, TRUTH, POSES, radius)


def test_a_map_that_holds_the_wall_neither_leaks_nor_blocks():
    m = metrics(wall_map())
    assert (m["leak"], m["block"], m["surface_recall"]) == (0.0, 0.0, 1.0)
    assert m["reachable_cells"] == m["truth_reachable_cells"] == BELOW


def test_a_gap_wider_than_the_robot_leaks_the_far_side():
    """A 6-cell (0.6 m) gap: columns 13-16 of rows 9, 10 and 11 are 2+ cells from the wall's
    ends, so the planner crosses and reaches all 224 cells above: 236 cells the robot cannot reach."""
    m = metrics(wall_map(gap=(12, 18)))
    assert m["leak"] == pytest.approx((3 * 4 + BELOW) / BELOW)
    assert m["block"] == 0.0
    # the wall's 30 surface cells; 12 and 17 lie 0.1 m from a cell above 0.5, 13-16 farther
    assert m["surface_recall"] == pytest.approx(26 / 30)
    # the gap's cells are at most 0.3 m from the wall's ends: a 0.35 m robot does not cross
    assert not map_reach(GRID, wall_map(gap=(12, 18)), OBSERVED, POSES, 0.35)[10:].any()


def test_a_gap_narrower_than_the_robot_does_not_leak():
    m = metrics(wall_map(gap=(14, 16)))  # 0.2 m: every gap cell is within 0.1 m of a wall cell
    assert (m["leak"], m["block"], m["surface_recall"]) == (0.0, 0.0, 1.0)


def test_a_phantom_wall_blocks():
    """A wall the truth does not have, across the lower half at column 20: the planner keeps
    columns 1-18 of rows 1-8 (144 of the 224 cells)."""
    p = wall_map()
    p[:10, 20] = 0.9
    m = metrics(p)
    assert m["block"] == pytest.approx((BELOW - 8 * 18) / BELOW)
    assert (m["leak"], m["surface_recall"]) == (0.0, 1.0)


def test_nothing_observed_is_not_a_number():
    m = metrics(wall_map(), observed=np.zeros(GRID.shape, dtype=bool))
    assert np.isnan(m["leak"]) and np.isnan(m["block"]) and np.isnan(m["surface_recall"])


def test_against_the_standard_map():
    """The standard map holds the wall at 0.95 (its 30 confident cells); a map with the 6-cell
    gap keeps 26 of them and reaches 236 cells beyond the standard map's 224: of these the 4 of
    row 9 lie 0.1 m from row 8, which the standard map reaches; the other 232 are far."""
    standard = wall_map(p_wall=0.95)
    gap = against_standard(GRID, wall_map(gap=(12, 18)), OBSERVED, standard, OBSERVED, POSES, RADIUS)
    assert gap == pytest.approx({"walls_kept": 26 / 30, "leak_vs_standard": (3 * 4 + BELOW) / BELOW,
                                 "far_leak": (2 * 4 + BELOW) / BELOW})
    itself = against_standard(GRID, standard, OBSERVED, standard, OBSERVED, POSES, RADIUS)
    assert itself == {"walls_kept": 1.0, "leak_vs_standard": 0.0, "far_leak": 0.0}
    unsure = against_standard(GRID, standard, OBSERVED, wall_map(p_wall=0.8), OBSERVED, POSES, RADIUS)
    assert np.isnan(unsure["walls_kept"])  # no cell at p >= 0.9 in the standard map to keep
    unseen = np.zeros(GRID.shape, dtype=bool)  # the standard map reaches nothing: no share to take
    blind = against_standard(GRID, standard, OBSERVED, standard, unseen, POSES, RADIUS)
    assert np.isnan(blind["leak_vs_standard"]) and np.isnan(blind["far_leak"])


def thick_wall(p_wall: float = 0.95) -> np.ndarray:
    """Probabilities: the wall five cells thick (rows 8-12) at ``p_wall``, free 0.1."""
    p = np.full(GRID.shape, 0.1)
    p[8:13, :] = p_wall
    return p


def test_far_leak_leaves_out_the_band_beside_the_standard_maps_reach():
    """The standard map draws the wall five cells thick (rows 8-12), the map one (row 10): the
    0.15 m robot drives rows 1-6 (columns 1-28: 168 cells) in the standard map and rows 1-8 in the
    map. Row 7 lies 0.1 m from row 6, inside the band; row 8 lies 0.2 m from it, beyond."""
    thin = against_standard(GRID, wall_map(), OBSERVED, thick_wall(), OBSERVED, POSES, RADIUS)
    assert thin["leak_vs_standard"] == pytest.approx(2 * 28 / 168)
    assert thin["far_leak"] == pytest.approx(28 / 168)
    assert thin["walls_kept"] == pytest.approx(3 / 5)  # rows 9-11 lie within 0.15 m of row 10; 8 and 12 not
    # a 0.2 m robot: columns 2-27, rows 2-5 in the standard map (104 cells), rows 2-7 in the map;
    # row 7 lies exactly 0.2 m from row 5, not farther: all of it band, no far leak
    wide = against_standard(GRID, wall_map(), OBSERVED, thick_wall(), OBSERVED, POSES, 0.2)
    assert (wide["leak_vs_standard"], wide["far_leak"]) == (pytest.approx(2 * 26 / 104), 0.0)


def test_far_leak_counts_what_gets_through_a_gap():
    """The one-cell wall with the 6-cell gap against the five-cell standard wall: 460 cells reached
    (224 below, the gap's 12, 224 above) beyond the standard map's 168 rows 1-6: 292; row 7's 28
    lie in the band, the other 264 are far."""
    gap = against_standard(GRID, wall_map(gap=(12, 18)), OBSERVED, thick_wall(), OBSERVED, POSES, RADIUS)
    assert gap["leak_vs_standard"] == pytest.approx(292 / 168)
    assert gap["far_leak"] == pytest.approx(264 / 168)


# --- aogm compare ---------------------------------------------------------------------------------

BEHIND_THE_WALL = """  - name: behind_the_wall
    blocked: {from: [1.0, 1.0], to: [1.0, 3.0], robot_radius: 0.2}
"""  # a third check, appended to the tiny door world's checks
TRUTH_KEYS = ("leak", "block", "surface_recall")
STANDARD_KEYS = ("walls_kept", "leak_vs_standard", "far_leak")


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def logs(tmp_path_factory, tiny_door_world):
    """A short log of a corridor with a door into a room (truth), and the same log without its truth."""
    folder = tmp_path_factory.mktemp("planner")
    text = tiny_door_world + BEHIND_THE_WALL
    world = parse_world(yaml.safe_load(text), file="tiny_door.yaml", text=text)
    log = simulate(world, seed=1)
    write_log(folder / "room.h5", log)
    write_log(folder / "bare.h5", dataclasses.replace(log, truth=None))
    return folder / "room.h5", folder / "bare.h5"


@pytest.fixture(scope="module")
def compared(logs, tmp_path_factory):
    out = tmp_path_factory.mktemp("cmp")
    result = run("compare", logs[0], "--modes", "standard,em", "--no-calibrate", "--json", out / "r.json", "--csv",
                 out / "r.csv", "--maps-dir", out / "maps", "--require", "em.leak <= 1", "-q")
    assert result.exit_code == 0, result.output
    return out, json.loads((out / "r.json").read_text()), result.output


def test_compare_reports_leak_block_and_surface_recall(logs, compared, read_csv):
    out, doc, output = compared
    assert "gates: 1 of 1 passed" in output
    assert all(name in output for name in ("Leak", "Block", "Surface"))
    poses = read_log(logs[0]).pose
    truth = read_log(logs[0]).truth
    for r in doc["results"]:
        assert set(TRUTH_KEYS) <= set(r["metrics"]) and not set(STANDARD_KEYS) & set(r["metrics"])
        m = read_map_file(out / "maps" / f"room_{r['mode']}.h5")
        expected = planner_metrics(m.grid, m.probability, m.observed, truth.occupancy, poses, 0.2)
        assert {k: r["metrics"][k] for k in TRUTH_KEYS} == pytest.approx({k: expected[k] for k in TRUTH_KEYS})
        assert [c["name"] for c in r["metrics"]["checks"]] == ["door_passable", "through_wall", "behind_the_wall"]
    header, rows = read_csv(out / "r.csv")
    assert header[header.index("checks_passed") + 1:][:6] == [*TRUTH_KEYS, *STANDARD_KEYS]
    for row, r in zip(rows, doc["results"], strict=True):
        assert [float(row[k]) for k in TRUTH_KEYS] == [r["metrics"][k] for k in TRUTH_KEYS]
        assert row["walls_kept"] == row["leak_vs_standard"] == row["far_leak"] == ""


def test_robot_radius_reaches_the_metrics_and_is_checked(logs, compared, tmp_path):
    out, doc, _ = compared
    maps = [out / "maps" / "room_standard.h5", out / "maps" / "room_em.h5"]
    wide = run("compare", *maps, "--robot-radius", 0.45, "--json", tmp_path / "w.json", "-q")
    assert wide.exit_code == 0, wide.output
    truth, poses = read_log(logs[0]).truth, read_log(logs[0]).pose
    for r in json.loads((tmp_path / "w.json").read_text())["results"]:
        m = read_map_file(out / "maps" / f"room_{r['mode']}.h5")
        expected = planner_metrics(m.grid, m.probability, m.observed, truth.occupancy, poses, 0.45)
        assert r["metrics"]["block"] == pytest.approx(expected["block"])
    for bad in ("0", "-0.1", "nan"):
        result = run("compare", *maps, "--robot-radius", bad, "-q")
        assert result.exit_code == 2 and "--robot-radius" in result.output and "Traceback" not in result.output
    refused = run("compare", "--from-json", out / "r.json", "--robot-radius", 0.3, "-q")
    assert refused.exit_code == 2 and "--robot-radius" in refused.output


def test_a_gate_on_a_planner_metric_fails_with_its_numbers(compared):
    out, doc, _ = compared
    leak = doc["results"][1]["metrics"]["leak"]
    result = run("compare", "--from-json", out / "r.json", "--require", "em.leak > 2", "-q")
    assert result.exit_code == 1
    assert f"FAILED tiny_door: em.leak > 2  ({leak:.6g} > 2)" in result.output


def test_from_json_reads_older_files_without_the_planner_metrics(compared, tmp_path, monkeypatch, read_csv):
    out, doc, _ = compared
    old = json.loads(json.dumps(doc))
    for r in old["results"]:
        for k in TRUTH_KEYS:
            del r["metrics"][k]
    (tmp_path / "old.json").write_text(json.dumps(old))

    def refuse(*args, **kwargs):
        raise AssertionError("mapped")

    monkeypatch.setattr(scoring, "map_one", refuse)
    result = run("compare", "--from-json", tmp_path / "old.json", "--json", tmp_path / "again.json", "--csv",
                 tmp_path / "again.csv", "--require", "em.accuracy >= 0", "-q")
    assert result.exit_code == 0, result.output
    assert "Leak" not in result.output
    again = json.loads((tmp_path / "again.json").read_text())
    assert again["results"] == old["results"]  # written back as read: no planner keys
    _, rows = read_csv(tmp_path / "again.csv")
    assert all(row[k] == "" for row in rows for k in TRUTH_KEYS)
    gated = run("compare", "--from-json", tmp_path / "old.json", "--require", "em.leak <= 1", "-q")
    assert gated.exit_code == 1 and "em.leak not available" in gated.output
    bad = json.loads(json.dumps(doc))
    bad["results"][0]["metrics"]["leak"] = "lots"
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    refused = run("compare", "--from-json", tmp_path / "bad.json", "-q")
    assert refused.exit_code == 2 and "results[0].metrics.leak: expected a number or null" in refused.output


def test_without_truth_every_map_is_compared_with_the_standard_map(logs, tmp_path, monkeypatch):
    """A log without truth: em against the standard map of the same log (made by em's own task
    when only em is compared), the standard map 1 and 0; given maps use the standard map given."""
    bare = logs[1]
    both = run("compare", bare, "--modes", "standard,em", "--no-calibrate", "--json", tmp_path / "b.json",
               "--maps-dir", tmp_path / "maps", "--require", "em.walls_kept >= 0", "-q")
    assert both.exit_code == 0, both.output
    assert "Walls kept" in both.output and "Leak vs std" in both.output and "Far leak" in both.output
    standard, em = json.loads((tmp_path / "b.json").read_text())["results"]
    assert standard["metrics"] == {"walls_kept": 1.0, "leak_vs_standard": 0.0, "far_leak": 0.0}
    assert set(em["metrics"]) == set(STANDARD_KEYS)
    maps = {mode: read_map_file(tmp_path / "maps" / f"bare_{mode}.h5") for mode in ("standard", "em")}
    poses = read_log(bare).pose
    expected = against_standard(maps["em"].grid, maps["em"].probability, maps["em"].observed,
                                maps["standard"].probability, maps["standard"].observed, poses, 0.2)
    assert em["metrics"] == pytest.approx(expected)
    alone = run("compare", bare, "--modes", "em", "--no-calibrate", "--json", tmp_path / "e.json", "-q")
    assert alone.exit_code == 0, alone.output
    assert json.loads((tmp_path / "e.json").read_text())["results"][0]["metrics"] == pytest.approx(expected)

    def refuse(*args, **kwargs):
        raise AssertionError("mapped")

    monkeypatch.setattr(scoring, "map_one", refuse)  # both maps given: the standard one is at hand
    given = run("compare", tmp_path / "maps" / "bare_standard.h5", tmp_path / "maps" / "bare_em.h5", "--json",
                tmp_path / "g.json", "-q")
    assert given.exit_code == 0, given.output
    assert json.loads((tmp_path / "g.json").read_text())["results"][1]["metrics"] == pytest.approx(expected)
    back = run("compare", "--from-json", tmp_path / "b.json", "--require", "em.leak_vs_standard >= 0",
               "--require", "em.far_leak <= em.leak_vs_standard", "-q")
    assert back.exit_code == 0, back.output
    assert "gates: 2 of 2 passed" in back.output


def test_from_json_reads_older_files_without_far_leak(logs, tmp_path, read_csv):
    """A file written before far_leak: read back with walls_kept and leak_vs_standard only,
    written again so, its CSV cells empty, and a gate naming it not available."""
    made = run("compare", logs[1], "--modes", "standard,em", "--no-calibrate", "--json", tmp_path / "b.json", "-q")
    assert made.exit_code == 0, made.output
    old = json.loads((tmp_path / "b.json").read_text())
    for r in old["results"]:
        del r["metrics"]["far_leak"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    back = run("compare", "--from-json", tmp_path / "old.json", "--json", tmp_path / "again.json", "--csv",
               tmp_path / "again.csv", "-q")
    assert back.exit_code == 0, back.output
    assert "Leak vs std" in back.output and "Far leak" not in back.output
    assert json.loads((tmp_path / "again.json").read_text())["results"] == old["results"]
    _, rows = read_csv(tmp_path / "again.csv")
    assert all(row["far_leak"] == "" and row["leak_vs_standard"] != "" for row in rows)
    gated = run("compare", "--from-json", tmp_path / "old.json", "--require", "em.far_leak <= 0.01", "-q")
    assert gated.exit_code == 1 and "em.far_leak not available" in gated.output


def test_the_figure_draws_what_the_planner_reaches(compared, tmp_path, monkeypatch):
    out, _, _ = compared
    from aogm_cli.report import figure

    tints = []
    monkeypatch.setattr(figure, "draw_reach", lambda ax, grid, reach, leaked=None: tints.append((reach, leaked)))
    result = run("compare", out / "maps" / "room_standard.h5", out / "maps" / "room_em.h5", "--figure",
                 tmp_path / "f.png", "-q")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"
    assert len(tints) == 2 and all(reach.any() and leaked is not None for reach, leaked in tints)
    assert all(not (leaked & ~reach).any() for reach, leaked in tints)  # leaked cells are reached ones

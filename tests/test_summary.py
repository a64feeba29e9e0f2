"""The summary over logs, the aggregate gates and the baseline of ``aogm compare``, on tiny results whose numbers are
worked out by hand: three logs of one world (standard and em), their means, standard deviations, Student-t
intervals, paired differences and wins; a baseline identical, moved, short of a log, changed, on a slower machine;
and the bad inputs that exit 2 with nothing written."""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.io.results import ModeResult, json_bytes
from aogm_cli.report.baseline import TOLERANCES, compare_to_baseline, parse_tolerances
from aogm_cli.report.gates import evaluate_gates, gate_values, parse_gate
from aogm_cli.report.summary import estimate, summarize

T_2 = 4.302652729911275  # t(0.975, 2): Student's t, two degrees of freedom (tables)
SQRT3 = math.sqrt(3)

# per log: standard (accuracy, leak, runtime), em (accuracy, leak, runtime)
ROWS = {
    "logs/door_1.h5": ((0.80, 0.10, 1.0), (0.90, 0.00, 10.0)),
    "logs/door_2.h5": ((0.84, 0.00, 2.0), (0.91, 0.00, 30.0)),
    "logs/door_3.h5": ((0.82, 0.05, 4.0), (0.89, 0.10, 20.0)),
}


def result(log: str, mode: str, accuracy: float, leak: float, runtime: float, content: str | None = None,
           passed: bool = True) -> ModeResult:
    metrics = {"accuracy": accuracy, "occupied_precision": 0.5, "occupied_recall": 0.5, "occupied_f1": 0.5,
               "brier": 0.1, "ece": 0.05, "checks": [{"name": "door_passable", "passed": passed}]}
    return ModeResult(log, "corridor_door", mode, runtime, metrics, None, planner={"leak": leak, "block": 0.0,
                      "surface_recall": 1.0}, log_content=content or "0" * 64)


def results(rows=ROWS, scale: float = 1.0) -> list[ModeResult]:
    return [result(log, mode, a, leak, t * scale)
            for log, pair in rows.items() for mode, (a, leak, t) in zip(("standard", "em"), pair, strict=True)]


def test_an_estimate_by_hand():
    e = estimate([0.80, 0.84, 0.82])
    assert e.n == 3 and e.mean == pytest.approx(0.82)
    assert e.sd == pytest.approx(0.02)  # sqrt((0.02^2 + 0.02^2 + 0) / 2)
    half = T_2 * 0.02 / SQRT3  # 0.049683
    assert (e.ci_low, e.ci_high) == (pytest.approx(0.82 - half), pytest.approx(0.82 + half))
    one = estimate([0.5])
    assert (one.n, one.mean, one.sd, one.ci_low, one.ci_high) == (1, 0.5, None, None, None)


def test_the_summary_of_three_logs_by_hand():
    s = summarize(results())
    assert [g.name for g in s.worlds] == ["corridor_door"] and s.all.logs == 3
    em = s.all.modes["em"]
    assert em["accuracy"].mean == pytest.approx(0.90) and em["accuracy"].sd == pytest.approx(0.01)
    ratio = em["runtime_ratio"]  # 10/1, 30/2, 20/4
    assert ratio.mean == pytest.approx(10.0) and ratio.sd == pytest.approx(5.0)
    assert ratio.ci_high - ratio.mean == pytest.approx(T_2 * 5.0 / SQRT3)
    d = {x.metric: x for x in s.all.differences if (x.mode, x.other) == ("em", "standard")}
    acc = d["accuracy"]  # differences 0.10, 0.07, 0.07
    assert acc.estimate.mean == pytest.approx(0.08) and acc.estimate.sd == pytest.approx(math.sqrt(0.0003))
    assert acc.estimate.ci_low == pytest.approx(0.08 - T_2 * 0.01)  # sqrt(0.0003) / sqrt(3) = 0.01
    assert (acc.wins, acc.ties, acc.losses) == (3, 0, 0)
    leak = d["leak"]  # -0.10 (better), 0 (tie), +0.05 (worse): lower is better
    assert leak.estimate.mean == pytest.approx(-0.05 / 3)
    assert (leak.wins, leak.ties, leak.losses) == (1, 1, 1)


def test_the_json_summary_agrees_with_the_rows(tmp_path):
    """compare --from-json's summary, recomputed from the per-log rows of its own --json file."""
    runs = tmp_path / "run.json"
    runs.write_bytes(json_bytes(results()))
    out = tmp_path / "merged.json"
    r = CliRunner().invoke(main, ["compare", "--from-json", str(runs), "--json", str(out), "-q"])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    rows = {(x["log"], x["mode"]): x for x in doc["results"]}
    logs = sorted({log for log, _ in rows})
    diffs = [rows[(g, "em")]["metrics"]["accuracy"] - rows[(g, "standard")]["metrics"]["accuracy"] for g in logs]
    mean = sum(diffs) / 3
    sd = math.sqrt(sum((x - mean) ** 2 for x in diffs) / 2)
    found = next(x for x in doc["summary"]["all"]["differences"] if x["metric"] == "accuracy" and x["mode"] == "em")
    assert found["mean"] == pytest.approx(mean) and found["sd"] == pytest.approx(sd)
    assert found["ci_low"] == pytest.approx(mean - T_2 * sd / SQRT3)
    assert doc["summary"]["worlds"]["corridor_door"]["modes"]["standard"]["leak"]["mean"] == pytest.approx(0.05)
    assert "summary over logs" not in r.output  # quiet: no titles, the tables still printed
    assert "em − standard" in r.output


@pytest.mark.parametrize(("text", "passes"), [
    ("mean(em.accuracy - standard.accuracy) >= 0.0799", True),
    ("mean(em.accuracy - standard.accuracy) >= 0.0801", False),
    ("ci_low(em.accuracy - standard.accuracy) > 0.036", True),  # 0.08 - 4.3027 * 0.01 = 0.03697
    ("ci_low(em.accuracy - standard.accuracy) > 0.038", False),
    ("min(em.checks_passed) == 1", True),
    ("max(em.leak) <= 0.05", False),
    ("median(em.runtime_ratio) <= 10", True),
    ("sd(em.accuracy) < 0.011", True),
])
def test_aggregate_gates_by_hand(text, passes):
    gate = parse_gate(text)
    count, failures = evaluate_gates([gate], gate_values(results()))
    assert count == 1 and (not failures) == passes
    if failures:
        assert failures[0].log_label == "all logs"


def test_per_log_gates_still_per_log():
    count, failures = evaluate_gates([parse_gate("em.leak <= 0.05")], gate_values(results()))
    assert count == 3 and len(failures) == 1


@pytest.mark.parametrize(("text", "message"), [
    ("mean(em.accuracy) >= standard.accuracy", "outside an aggregate"),
    ("mean(min(em.accuracy)) > 0", "do not nest"),
])
def test_malformed_aggregates_exit_2(text, message):
    with pytest.raises(InputError, match=message):
        parse_gate(text)


def test_an_aggregate_over_a_metric_one_log_lacks_is_bad_input():
    rs = results()
    rs[0].planner = {}  # door_1's standard map: no leak measured
    with pytest.raises(InputError, match="door_1.h5 has no standard.leak"):
        evaluate_gates([parse_gate("mean(standard.leak) < 1")], gate_values(rs))
    with pytest.raises(InputError, match="no log to aggregate over"):
        evaluate_gates([parse_gate("mean(em.accuracy) > 0")], [])
    with pytest.raises(InputError, match="at least two"):
        evaluate_gates([parse_gate("ci_low(em.accuracy) > 0")], gate_values(results()[:2]))


def test_a_baseline_identical_to_the_run_finds_nothing():
    report = compare_to_baseline(results(), results(), "old.json", TOLERANCES)
    assert report.compared > 0 and not report.regressions and not report.improvements
    assert not report.only_in_baseline and not report.only_in_run and not report.changed_logs


def test_a_metric_moved_past_its_tolerance_is_a_regression_and_within_it_is_not():
    old = results()
    old[1].metrics = {**old[1].metrics, "accuracy": 0.906}  # door_1 em was 0.906, now 0.90: within 0.005? no
    old[3].metrics = {**old[3].metrics, "accuracy": 0.913}  # door_2 em 0.913 -> 0.91: within
    report = compare_to_baseline(results(), old, "old.json", TOLERANCES)
    assert [(c.where, c.mode, c.metric) for c in report.regressions] == [("door_1.h5", "em", "accuracy")]
    assert report.regressions[0].old == 0.906 and report.regressions[0].new == 0.90
    loose = compare_to_baseline(results(), old, "old.json", parse_tolerances("accuracy=0.01"))
    assert not loose.regressions


def test_a_slower_machine_is_not_a_regression_but_a_slower_mode_is():
    twice = compare_to_baseline(results(scale=2.0), results(), "old.json", TOLERANCES)
    assert not twice.regressions  # every map twice as slow: the ratios to standard are the same
    slower = results()
    slower[1].runtime_s *= 2  # door_1's em alone: x10 -> x20 its standard map; the mean x10 -> x13.3
    report = compare_to_baseline(slower, results(), "old.json", TOLERANCES)
    assert [(c.where, c.metric) for c in report.regressions] == [("door_1.h5", "runtime_ratio"),
                                                                 ("world corridor_door, mean of 3 logs", "runtime_ratio")]


def test_logs_on_one_side_and_changed_logs_are_named_not_compared():
    old = results() + [result("elsewhere/door_9.h5", "em", 0.9, 0.0, 1.0)]
    new = results()
    new[4].log_content = new[5].log_content = "f" * 64  # door_3 simulated otherwise
    new[4].metrics = {**new[4].metrics, "accuracy": 0.1}
    report = compare_to_baseline(new, old, "old.json", TOLERANCES)
    assert report.only_in_baseline == [("door_9.h5", "em")]
    assert report.changed_logs == ["door_3.h5"] and not report.regressions


def test_a_worlds_mean_beyond_tolerance_is_a_regression():
    old = results()
    for r in old[1::2]:  # every em map 0.004 more accurate before: each log within 0.005, the mean too
        r.metrics = {**r.metrics, "accuracy": r.metrics["accuracy"] + 0.004}
    assert not compare_to_baseline(results(), old, "old.json", TOLERANCES).regressions
    report = compare_to_baseline(results(), old, "old.json", parse_tolerances("accuracy=0.003"))
    assert ("world corridor_door, mean of 3 logs", "em", "accuracy") in {(c.where, c.mode, c.metric)
                                                                          for c in report.regressions}


def _compare(tmp_path, old_doc: bytes | str, *extra):
    run, old = tmp_path / "run.json", tmp_path / "old.json"
    run.write_bytes(json_bytes(results()))
    old.write_bytes(old_doc.encode() if isinstance(old_doc, str) else old_doc)
    out = tmp_path / "out.json"
    r = CliRunner().invoke(main, ["compare", "--from-json", str(run), "--baseline", str(old), "--json", str(out),
                                  "--markdown", str(tmp_path / "out.md"), "--summary-only", "-q", *extra])
    return r, out


def test_cli_baseline_identical_exits_0_and_moved_exits_1_naming_it(tmp_path):
    r, out = _compare(tmp_path, json_bytes(results()))
    assert r.exit_code == 0, r.output
    assert json.loads(out.read_text())["baseline"]["regressions"] == []
    old = results()
    old[5].metrics = {**old[5].metrics, "accuracy": 0.95}
    r, out = _compare(tmp_path, json_bytes(old))
    assert r.exit_code == 1
    assert "REGRESSION door_3.h5 em.accuracy: 0.95 -> 0.89" in r.output
    assert "| door_3.h5 | em | accuracy | 0.95 | 0.89 |" in (tmp_path / "out.md").read_text()


@pytest.mark.parametrize(("old_doc", "extra", "message"), [
    ('{"format": "something else"}', (), "old.json: format"),
    (json_bytes(results()).decode().replace('"format_version": 1', '"format_version": 2'), (), "format_version"),
    ("not json", (), "not JSON"),
    (json_bytes(results()), ("--tolerance", "accuracy=-1"), "--tolerance"),
    (json_bytes(results()), ("--tolerance", "speed=2"), "expected METRIC=VALUE"),
    (json_bytes(results()), ("--tolerance", "runtime=0.5"), "a factor >= 1"),
])
def test_cli_bad_baselines_and_tolerances_exit_2_writing_nothing(tmp_path, old_doc, extra, message):
    r, out = _compare(tmp_path, old_doc, *extra)
    assert r.exit_code == 2 and message in r.output, r.output
    assert not out.exists() and not (tmp_path / "out.md").exists()


def test_cli_tolerance_without_baseline_and_a_bad_aggregate_exit_2(tmp_path):
    run = tmp_path / "run.json"
    run.write_bytes(json_bytes(results()))
    r = CliRunner().invoke(main, ["compare", "--from-json", str(run), "--tolerance", "accuracy=0.01"])
    assert r.exit_code == 2 and "--tolerance" in r.output
    out = tmp_path / "out.json"
    r = CliRunner().invoke(main, ["compare", "--from-json", str(run), "--json", str(out), "--require",
                                  "mean(em.holdout_auc) > 0.5"])
    assert r.exit_code == 2 and not out.exists()


def test_check_counts_per_mode():
    rs = results()
    rs[0].metrics = {**rs[0].metrics, "checks": [{"name": "door_passable", "passed": False}]}
    s = summarize(rs)
    assert s.all.checks == {"standard": {"door_passable": (2, 3)}, "em": {"door_passable": (3, 3)}}
    assert s.as_dict()["worlds"]["corridor_door"]["checks"]["standard"]["door_passable"] == {"passed": 2, "logs": 3}


def test_an_estimate_has_its_median_and_range():
    e = estimate([10.0, 15.0, 5.0, 40.0])
    assert (e.median, e.min, e.max) == (12.5, 5.0, 40.0)


def test_the_printed_summary_shows_worlds_of_several_logs_and_all_logs(tmp_path):
    """make demo's run (one log per world) prints the summary over all logs only; a world's checks per world."""
    from aogm_cli.report.summary_table import check_lines, groups

    one_each = results()
    for r, world in zip(one_each, ("a", "a", "b", "b", "c", "c"), strict=True):
        r.world = world
    s = summarize(one_each)
    assert [g.name for g in groups(s)] == ["all"] and check_lines(s) == []
    s = summarize(results())
    assert [g.name for g in groups(s)] == ["corridor_door"]
    assert check_lines(s) == ["checks passed, corridor_door: standard door_passable 3/3, em door_passable 3/3"]

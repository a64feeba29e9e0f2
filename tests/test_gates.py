"""The --require expression parser of ``aogm compare``: precedence, parentheses, names, division."""

import math

import pytest

from aogm_cli.core.errors import InputError
from aogm_cli.report.gates import (
    check_gate_modes,
    evaluate_gates,
    evaluate_required_checks,
    parse_gate,
    tokenize,
)


def sides(text, **values):
    """(left, right, passed) of a gate with values given as mode__metric=..."""
    vals = {tuple(k.split("__")): v for k, v in values.items()}
    out = parse_gate(text).evaluate(vals)
    return out.left, out.right, out.passed


def test_multiplication_binds_tighter_than_addition():
    assert sides("em.runtime == 1 + 2 * 3", em__runtime=7.0) == (7.0, 7.0, True)
    assert sides("2 * 3 - 1 < em.runtime", em__runtime=5.5) == (5.0, 5.5, True)
    assert sides("em.accuracy >= standard.accuracy - 0.005", em__accuracy=0.9, standard__accuracy=0.9)[2]


def test_parentheses_override_precedence():
    assert sides("(1 + 2) * 3 == em.runtime", em__runtime=9.0) == (9.0, 9.0, True)
    assert sides("2 * (em.runtime - (1 - 4)) > 0", em__runtime=1.0)[0] == 8.0


def test_left_associative_minus_and_division():
    assert sides("em.runtime - 1 - 1 == 3", em__runtime=5.0)[0] == 3.0
    assert sides("12 / 3 / 2 == em.runtime", em__runtime=2.0) == (2.0, 2.0, True)
    assert sides("adaptive.runtime / standard.runtime <= 1.5", adaptive__runtime=0.3, standard__runtime=0.2)[0] == pytest.approx(1.5)


def test_unary_signs_and_number_forms():
    assert sides("-em.brier < -0.01", em__brier=0.02) == (-0.02, -0.01, True)
    assert sides("--em.brier == +0.02", em__brier=0.02)[2]
    assert sides("em.brier <= 1e-1 + .5", em__brier=0.0)[1] == pytest.approx(0.6)


@pytest.mark.parametrize("op, expected", [("<", False), ("<=", True), (">", False), (">=", True), ("==", True), ("!=", False)])
def test_every_comparison(op, expected):
    assert sides(f"em.accuracy {op} 0.5", em__accuracy=0.5)[2] is expected


def test_division_by_zero_fails_the_gate_with_a_reason():
    gate = parse_gate("em.runtime / standard.runtime <= 2")
    out = gate.evaluate({("em", "runtime"): 1.0, ("standard", "runtime"): 0.0})
    assert not out.passed and out.reason == "division by zero"
    assert "division by zero" in gate.describe_failure(out)


def test_failure_message_substitutes_the_numbers():
    gate = parse_gate("adaptive.runtime <= 1.5 * standard.runtime")
    out = gate.evaluate({("adaptive", "runtime"): 0.42, ("standard", "runtime"): 0.21})
    assert not out.passed
    assert out.substituted == "0.42 <= 1.5 * 0.21"
    message = gate.describe_failure(out)
    assert message.startswith("adaptive.runtime <= 1.5 * standard.runtime  (0.42 <= 1.5 * 0.21")
    assert "0.42 <= 0.315" in message  # the evaluated right side


def test_a_missing_value_fails_and_says_so():
    gate = parse_gate("em.accuracy >= 0.9")
    out = gate.evaluate({("em", "accuracy"): None})
    assert not out.passed and "em.accuracy not available" in out.reason and out.substituted == "n/a >= 0.9"


@pytest.mark.parametrize(
    "text, words",
    [
        ("foo.accuracy > 1", "unknown mode 'foo'"),
        ("em.acc > 1", "unknown metric 'acc'"),
        ("accuracy > 1", "expected MODE.METRIC"),
        ("em.accuracy.x > 1", "expected MODE.METRIC"),
        ("em.runtime_s > 1", "unknown metric 'runtime_s'"),
    ],
)
def test_unknown_names_are_input_errors_naming_require(text, words):
    with pytest.raises(InputError) as err:
        parse_gate(text)
    assert err.value.key == "--require" and words in str(err.value) and text in str(err.value)


@pytest.mark.parametrize(
    "text, words",
    [
        ("", "empty expression"),
        ("em.accuracy", "one comparison"),
        ("em.accuracy >=", "found the end"),
        ("em.accuracy >= 1 >= 2", "exactly one comparison"),
        ("(em.accuracy >= 1", "expected ')'"),
        ("em.accuracy >= (1 + 2", "expected ')'"),
        ("em.accuracy >= 1)", "found ')'"),
        ("em.accuracy >= 1 2", "found '2'"),
        ("em.accuracy = 1", "unexpected character '='"),
        ("em.accuracy >= 1; import os", "unexpected character ';'"),
        ("em.accuracy >= 2 ** 3", "found '*'"),
        ("__import__('os') > 1", "unexpected character"),
    ],
)
def test_malformed_expressions_are_input_errors(text, words):
    with pytest.raises(InputError) as err:
        parse_gate(text)
    assert err.value.key == "--require" and words in str(err.value)


def test_tokens_keep_their_positions():
    tokens = tokenize(" em.brier<=0.1")
    assert [(t.kind, t.text, t.start) for t in tokens] == [
        ("name", "em.brier", 1), ("op", "<=", 9), ("number", "0.1", 11), ("end", "", 14)
    ]


def test_gate_modes_must_be_compared():
    gates = [parse_gate("adaptive.accuracy >= em.accuracy")]
    check_gate_modes(gates, ("standard", "em", "adaptive"))
    with pytest.raises(InputError, match="'adaptive' is not among the modes compared"):
        check_gate_modes(gates, ("standard", "em"))


def test_gates_are_evaluated_per_log():
    gates = [parse_gate("em.accuracy >= standard.accuracy")]
    logs = [
        ("door", {("em", "accuracy"): 0.9, ("standard", "accuracy"): 0.8}),
        ("hall", {("em", "accuracy"): 0.7, ("standard", "accuracy"): 0.8}),
    ]
    count, failures = evaluate_gates(gates, logs)
    assert count == 2 and len(failures) == 1
    assert str(failures[0]) == "FAILED hall: em.accuracy >= standard.accuracy  (0.7 >= 0.8)"


def test_required_checks_fail_on_any_failed_check_or_missing_truth():
    ok = [{"name": "door", "passed": True}]
    bad = [{"name": "door", "passed": True}, {"name": "hall", "passed": False}]
    count, failures = evaluate_required_checks(["em"], [("a", {"em": ok, "standard": bad}), ("b", {"em": bad}), ("c", {"em": None})])
    assert count == 3
    assert [f.log_label for f in failures] == ["b", "c"]
    assert "1/2 passed; failed: hall" in str(failures[0]) and "no truth" in str(failures[1])
    assert evaluate_required_checks(["em"], [("a", {"em": []})]) == (1, [])  # no checks: nothing fails


def test_nan_values_fail():
    out = parse_gate("em.accuracy > 0").evaluate({("em", "accuracy"): math.nan})
    assert not out.passed


def test_deep_nesting_and_long_expressions_are_refused_not_a_recursion_error():
    for text in ("(" * 10000 + "em.accuracy" + ")" * 10000 + " > 0", "-" * 10000 + "1 > 0",
                 "(" * 60 + "1" + ")" * 60 + " > 0", " + ".join(["em.accuracy"] * 1000) + " > 0"):
        with pytest.raises(InputError) as info:
            parse_gate(text)
        assert info.value.key == "--require" and len(str(info.value)) < 300
    assert parse_gate("(" * 20 + "em.accuracy" + ")" * 20 + " > 0")

"""Quality gates of ``aogm compare``: ``--require`` expressions over ``mode.metric`` names, read by a
tiny parser (no eval: numbers, names, + - * /, parentheses, aggregates such as ``mean(...)`` and exactly one
comparison); a gate is evaluated per log, or once over every log when it aggregates, and a failure reads with
the numbers substituted."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass

from aogm_cli.core.errors import InputError
from aogm_cli.core.occupancy_map import MODES
from aogm_cli.core.scores import SCORE_KEYS, STANDARD_KEYS, TRUTH_KEYS
from aogm_cli.io.results import ModeResult
from aogm_cli.report import summary

# metric names of a gate -> what they mean; runtime is runtime_s, checks_passed a fraction; what a
# planner sees (``evaluation.planner``: leak, block, surface_recall with truth, walls_kept,
# leak_vs_standard and far_leak without); the held-out scores (``evaluation.holdout``) exist only with --holdout
HOLDOUT_METRICS = SCORE_KEYS
METRICS = ("accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "brier", "ece", "runtime",
           summary.RUNTIME_RATIO, "checks_passed", *TRUTH_KEYS, *STANDARD_KEYS, *HOLDOUT_METRICS)
# aggregates over the logs of a run: FUNCTION(expression of mode.metric names), the expression evaluated per log
AGGREGATES = ("mean", "sd", "ci_low", "ci_high", "min", "max", "median")
COMPARISONS = ("<=", ">=", "==", "!=", "<", ">")
OPTION = "--require"
MAX_LENGTH = 500  # characters of one expression
MAX_DEPTH = 50  # nested parentheses and signs: the parser and the evaluator recurse this deep

_TOKEN = re.compile(
    r"(?:"
    r"(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
    r"|(?P<name>[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*)"
    r"|(?P<op><=|>=|==|!=|<|>|[-+*/()])"
    r")"
)


@dataclass(frozen=True)
class Token:
    kind: str  # number, name, op, end
    text: str
    start: int
    end: int


# Expression nodes: ("num", value) | ("name", (mode, metric)) | ("neg", node) | (op, left, right)
# | ("agg", function, inner node, (start, end) of the aggregate's text)
Node = tuple


@dataclass(frozen=True)
class GateOutcome:
    """The result of one gate on one log (or over the logs, when it aggregates): passed, and the expression
    with numbers substituted."""

    passed: bool
    substituted: str
    left: float
    right: float
    reason: str = ""  # why it could not be evaluated (a missing value, a division by zero)


@dataclass(frozen=True)
class Gate:
    """A parsed ``--require`` expression: ``left OP right``; ``aggregates``: the spans of its aggregates (none:
    a gate per log; some: one gate over every log, each name inside an aggregate)."""

    text: str
    left: Node
    op: str
    right: Node
    names: tuple[tuple[str, str], ...]  # (mode, metric) in order of appearance, with the token spans
    spans: tuple[tuple[int, int], ...]
    aggregates: tuple[tuple[int, int], ...] = ()

    @property
    def modes(self) -> set[str]:
        return {mode for mode, _ in self.names}

    @property
    def over_logs(self) -> bool:
        """Whether the gate aggregates over the logs of the run (evaluated once, by ``evaluate_over``)."""
        return bool(self.aggregates)

    def evaluate(self, values: Mapping[tuple[str, str], float | None]) -> GateOutcome:
        """Evaluate on one log; ``values[(mode, metric)]`` is None when unavailable (no truth)."""
        substituted = self.substitute(values)
        missing = [f"{m}.{k}" for m, k in self.names if values.get((m, k)) is None]
        if missing:
            return GateOutcome(False, substituted, math.nan, math.nan, f"{', '.join(dict.fromkeys(missing))} not available")
        return self._outcome(self.left, self.right, values, substituted)

    def evaluate_over(self, logs: list[tuple[str, Mapping[tuple[str, str], float | None]]]) -> GateOutcome:
        """Evaluate an aggregating gate once over ``logs`` ((label, values) each). InputError (exit 2) when there
        is no log, when a log lacks a value an aggregate names, or when an aggregate needs more logs."""
        found: dict[tuple[int, int], float] = {}
        left, right = _resolved(self.left, logs, self.text, found), _resolved(self.right, logs, self.text, found)
        out, last = [], 0
        for start, end in self.aggregates:
            out += [self.text[last:start], format_number(found[(start, end)])]
            last = end
        return self._outcome(left, right, {}, "".join([*out, self.text[last:]]).strip())

    def _outcome(self, left_node: Node, right_node: Node, values, substituted: str) -> GateOutcome:
        try:
            left = _value(left_node, values)
            right = _value(right_node, values)
        except ZeroDivisionError:
            return GateOutcome(False, substituted, math.nan, math.nan, "division by zero")
        if math.isnan(left) or math.isnan(right):
            return GateOutcome(False, substituted, left, right, "not a number")
        return GateOutcome(_compare(left, self.op, right), substituted, left, right)

    def substitute(self, values: Mapping[tuple[str, str], float | None]) -> str:
        """The expression's text with each name replaced by its value (``n/a`` when missing)."""
        out, last = [], 0
        for (mode, metric), (start, end) in zip(self.names, self.spans, strict=True):
            v = values.get((mode, metric))
            out.append(self.text[last:start])
            out.append("n/a" if v is None else format_number(v))
            last = end
        out.append(self.text[last:])
        return "".join(out).strip()

    def describe_failure(self, outcome: GateOutcome) -> str:
        """``EXPR  (substituted)`` plus the evaluated sides when either side is compound."""
        detail = outcome.substituted
        if outcome.reason:
            detail += f"; {outcome.reason}"
        elif self.left[0] not in ("num", "name", "agg") or self.right[0] not in ("num", "name", "agg"):
            detail += f"; {format_number(outcome.left)} {self.op} {format_number(outcome.right)}"
        return f"{self.text.strip()}  ({detail})"


def _names_in(node: Node) -> list[tuple[str, str]]:
    """The (mode, metric) names of an aggregate's expression (which holds no aggregate), in order."""
    kind = node[0]
    if kind == "num":
        return []
    if kind == "name":
        return [node[1]]
    if kind == "neg":
        return _names_in(node[1])
    return _names_in(node[1]) + _names_in(node[2])


def _aggregate(node: Node, logs, text: str) -> float:
    """The value of one aggregate node over ``logs``; InputError (exit 2) when it cannot be computed."""
    function, inner, (start, end) = node[1], node[2], node[3]
    shown = text[start:end]
    if not logs:
        raise _error(text, f"{shown}: no log to aggregate over; expected at least one")
    xs = []
    for label, values in logs:
        missing = [f"{m}.{k}" for m, k in _names_in(inner) if not summary.known(values.get((m, k)))]
        if missing:
            raise _error(text, f"{shown}: the log {label} has no {', '.join(dict.fromkeys(missing))}; expected every "
                               "log of the run to have it (leave that log out, or gate per log)")
        try:
            xs.append(_value(inner, values))
        except ZeroDivisionError:
            raise _error(text, f"{shown}: division by zero on the log {label}") from None
    if function in ("sd", "ci_low", "ci_high") and len(xs) < 2:
        raise _error(text, f"{shown}: {len(xs)} log; expected at least two for {function}")
    return getattr(summary.estimate(xs), function)


def _resolved(node: Node, logs, text: str, found: dict) -> Node:
    """``node`` with each aggregate replaced by its value over ``logs`` (recorded in ``found`` by its span)."""
    kind = node[0]
    if kind == "agg":
        found[node[3]] = _aggregate(node, logs, text)
        return ("num", found[node[3]])
    if kind in ("num", "name"):
        return node
    if kind == "neg":
        return ("neg", _resolved(node[1], logs, text, found))
    return (kind, _resolved(node[1], logs, text, found), _resolved(node[2], logs, text, found))


def format_number(v: float) -> str:
    return f"{v:.6g}"


def _compare(a: float, op: str, b: float) -> bool:
    return {"<=": a <= b, ">=": a >= b, "==": a == b, "!=": a != b, "<": a < b, ">": a > b}[op]


def _value(node: Node, values) -> float:
    kind = node[0]
    if kind == "num":
        return node[1]
    if kind == "name":
        return float(values[node[1]])
    if kind == "neg":
        return -_value(node[1], values)
    a, b = _value(node[1], values), _value(node[2], values)
    if kind == "+":
        return a + b
    if kind == "-":
        return a - b
    if kind == "*":
        return a * b
    return a / b  # "/": ZeroDivisionError is reported by Gate.evaluate


def tokenize(text: str) -> list[Token]:
    """Tokens of ``text``; an InputError names the first character that is not part of one."""
    tokens, pos = [], 0
    while True:
        while pos < len(text) and text[pos].isspace():
            pos += 1
        if pos == len(text):
            break
        m = _TOKEN.match(text, pos)
        if not m:
            raise _error(text, f"unexpected character {text[pos]!r} at position {pos + 1}")
        kind = m.lastgroup
        tokens.append(Token(kind, m.group(kind), m.start(kind), m.end(kind)))
        pos = m.end()
    tokens.append(Token("end", "", len(text), len(text)))
    return tokens


def _error(text: str, message: str) -> InputError:
    shown = text.strip()
    shown = shown if len(shown) <= 80 else shown[:60] + "..." + shown[-15:]
    return InputError(f"{shown!r}: {message}", key=OPTION)


class _Parser:
    """Recursive descent: gate := expr CMP expr; expr := term (+|- term)*; term := factor (*|/ factor)*;
    factor := (+|-) factor | number | mode.metric | ( expr ) | AGGREGATE ( expr ); a gate with an aggregate has
    every name inside one, and aggregates do not nest."""

    def __init__(self, text: str):
        self.text = text
        self.tokens = tokenize(text)
        self.i = 0
        self.depth = 0
        self.names: list[tuple[str, str]] = []
        self.spans: list[tuple[int, int]] = []
        self.aggregates: list[tuple[int, int]] = []
        self.inside = False  # parsing an aggregate's expression
        self.outside: list[str] = []  # names met outside any aggregate

    def peek(self) -> Token:
        return self.tokens[self.i]

    def take(self) -> Token:
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def unexpected(self, tok: Token, expected: str) -> InputError:
        found = "the end" if tok.kind == "end" else repr(tok.text)
        return _error(self.text, f"expected {expected}, found {found}")

    def gate(self) -> Gate:
        left = self.expr()
        tok = self.take()
        if tok.kind != "op" or tok.text not in COMPARISONS:
            raise self.unexpected(tok, f"an operator or one comparison ({' '.join(COMPARISONS)})")
        right = self.expr()
        end = self.take()
        if end.kind == "op" and end.text in COMPARISONS:
            raise _error(self.text, "expected exactly one comparison, found a second one")
        if end.kind != "end":
            raise self.unexpected(end, "an operator or the end")
        if self.aggregates and self.outside:
            raise _error(self.text, f"{self.outside[0]} is outside an aggregate in a gate that aggregates; expected "
                                    f"every name inside one of {', '.join(AGGREGATES)}, e.g. mean(em.accuracy)")
        return Gate(self.text, left, tok.text, right, tuple(self.names), tuple(self.spans), tuple(self.aggregates))

    def expr(self) -> Node:
        node = self.term()
        while self.peek().kind == "op" and self.peek().text in ("+", "-"):
            op = self.take().text
            node = (op, node, self.term())
        return node

    def term(self) -> Node:
        node = self.factor()
        while self.peek().kind == "op" and self.peek().text in ("*", "/"):
            op = self.take().text
            node = (op, node, self.factor())
        return node

    def factor(self) -> Node:
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise _error(self.text, f"nested more than {MAX_DEPTH} deep (parentheses and signs); expected a simpler expression")
            return self._factor()
        finally:
            self.depth -= 1

    def _factor(self) -> Node:
        tok = self.take()
        if tok.kind == "op" and tok.text in ("+", "-"):
            inner = self.factor()
            return inner if tok.text == "+" else ("neg", inner)
        if tok.kind == "number":
            return ("num", float(tok.text))
        if tok.kind == "name" and tok.text in AGGREGATES and self.peek().text == "(":
            return self.aggregate(tok)
        if tok.kind == "name":
            name = self.name(tok)
            self.names.append(name)
            self.spans.append((tok.start, tok.end))
            if not self.inside:
                self.outside.append(tok.text)
            return ("name", name)
        if tok.kind == "op" and tok.text == "(":
            node = self.expr()
            close = self.take()
            if close.kind != "op" or close.text != ")":
                raise self.unexpected(close, "')'")
            return node
        raise self.unexpected(tok, "a number, a name such as em.accuracy, or '('")

    def aggregate(self, tok: Token) -> Node:
        """``FUNCTION ( expr )`` after its name ``tok``: an aggregate over the logs of the run."""
        if self.inside:
            raise _error(self.text, f"{tok.text}( inside another aggregate; expected aggregates that do not nest")
        self.take()  # "("
        self.inside = True
        inner = self.expr()
        self.inside = False
        close = self.take()
        if close.kind != "op" or close.text != ")":
            raise self.unexpected(close, "')'")
        self.aggregates.append((tok.start, close.end))
        return ("agg", tok.text, inner, (tok.start, close.end))

    def name(self, tok: Token) -> tuple[str, str]:
        parts = tok.text.split(".")
        if len(parts) != 2:
            raise _error(self.text, f"unknown name {tok.text!r}; expected MODE.METRIC, e.g. em.accuracy, or an "
                                    f"aggregate ({', '.join(AGGREGATES)}) of them")
        mode, metric = parts
        if mode not in MODES:
            raise _error(self.text, f"unknown mode {mode!r} in {tok.text!r}; expected one of {', '.join(MODES)}")
        if metric not in METRICS:
            raise _error(self.text, f"unknown metric {metric!r} in {tok.text!r}; expected one of {', '.join(METRICS)}")
        return (mode, metric)


def parse_gate(text: str) -> Gate:
    """Parse one ``--require`` expression; InputError (key ``--require``) when malformed."""
    if not text.strip():
        raise _error(text, "empty expression; expected e.g. 'adaptive.accuracy >= em.accuracy - 0.005'")
    if len(text) > MAX_LENGTH:
        raise _error(text, f"{len(text)} characters long; expected at most {MAX_LENGTH}")
    return _Parser(text).gate()


def check_gate_modes(gates: list[Gate], modes: tuple[str, ...]) -> None:
    """Every mode a gate names must be among the modes compared."""
    for gate in gates:
        for mode in sorted(gate.modes - set(modes), key=MODES.index):
            raise _error(gate.text, f"mode {mode!r} is not among the modes compared ({', '.join(modes)}); add it to --modes")


def check_gate_metrics(gates: list[Gate], holdout: bool) -> None:
    """The held-out scores a gate names are computed only with --holdout."""
    for gate in gates:
        for mode, metric in gate.names:
            if metric in HOLDOUT_METRICS and not holdout:
                raise _error(gate.text, f"metric {metric!r} of {mode}.{metric} is computed only with --holdout; "
                                        "add e.g. --holdout 0.1")


@dataclass(frozen=True)
class GateFailure:
    """One failed gate on one log, ready to print."""

    log_label: str
    message: str

    def __str__(self) -> str:
        return f"FAILED {self.log_label}: {self.message}"


ALL_LOGS = "all logs"  # the label of a failed gate that aggregates over the logs


def evaluate_gates(
    gates: list[Gate], logs: list[tuple[str, Mapping[tuple[str, str], float | None]]]
) -> tuple[int, list[GateFailure]]:
    """Evaluate every gate per log ``(label, values)``, or once over them when it aggregates: (number evaluated,
    failures)."""
    failures, count = [], 0
    for label, values in logs:
        for gate in gates:
            if gate.over_logs:
                continue
            count += 1
            outcome = gate.evaluate(values)
            if not outcome.passed:
                failures.append(GateFailure(label, gate.describe_failure(outcome)))
    for gate in gates:
        if gate.over_logs:
            count += 1
            outcome = gate.evaluate_over(logs)
            if not outcome.passed:
                failures.append(GateFailure(ALL_LOGS, gate.describe_failure(outcome)))
    return count, failures


def evaluate_required_checks(
    modes: list[str], logs: list[tuple[str, Mapping[str, list[dict] | None]]]
) -> tuple[int, list[GateFailure]]:
    """``--require-checks MODE``: every check of every log ``(label, {mode: checks})`` passes in
    each of ``modes``; checks None means the log has no truth, which fails (nothing to verify)."""
    failures, count = [], 0
    for label, checks_by_mode in logs:
        for mode in modes:
            count += 1
            checks = checks_by_mode.get(mode)
            if checks is None:
                failures.append(GateFailure(label, f"{mode} checks  (the log has no truth to check)"))
                continue
            failed = [c["name"] for c in checks if not c["passed"]]
            if failed:
                passed = len(checks) - len(failed)
                failures.append(GateFailure(label, f"{mode} checks  ({passed}/{len(checks)} passed; failed: {', '.join(failed)})"))
    return count, failures


def gate_values(results: list[ModeResult]) -> list[tuple[str, dict[tuple[str, str], float | None]]]:
    """Per log (in order): (log path, {(mode, metric): value}) (``summary.log_values``)."""
    return list(summary.log_values(results).items())


def evaluate_comparison_gates(gates: list[Gate], require_checks: list[str], results: list[ModeResult],
                              labels: dict[str, str]) -> tuple[int, list[GateFailure]]:
    """``--require`` and ``--require-checks`` evaluated per log of a comparison's ``results``
    (``labels`` names the logs, ``report.table.log_labels``): (number evaluated, failures)."""
    per_log = [(labels[log], values) for log, values in gate_values(results)]
    n_gates, failures = evaluate_gates(gates, per_log)
    checks_by_log: dict[str, dict] = {}
    for r in results:
        checks_by_log.setdefault(labels[r.log], {})[r.mode] = None if r.metrics is None else r.metrics["checks"]
    n_checks, check_failures = evaluate_required_checks(list(require_checks), list(checks_by_log.items()))
    return n_gates + n_checks, failures + check_failures

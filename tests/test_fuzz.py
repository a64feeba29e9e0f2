"""Issue 12, the fuzz half: property-based damage (hypothesis) to world files and to the bytes and
objects of each HDF5 file kind (log, map, detector), each fed to the command that reads it.

The property, for every example: the command exits 0 or 2 (never 1 or anything else: nothing here
is an OS failure), prints no traceback, on 2 names the damaged file, leaves no output file when it
fails and no temporary ``.*.tmp`` either way, leaves its input unchanged, and ends within
``HANG_SECONDS``. Each example runs in a forked child (the parent has compiled the kernels, so a
child costs milliseconds), so that a hang can be stopped and a crash of the HDF5 library (a
signal) is counted instead of ending the test run.

``AOGM_FUZZ_EXAMPLES`` sets the examples per file kind (default 15, for ``make test``); ``make
fuzz`` runs 2000 and prints, per kind, the examples, crashes, hangs, other exits, partial outputs
and the time taken. The seed is fixed (``derandomize``) and no example database is kept, so a run
is reproducible (hypothesis still caches constants in ``.hypothesis/``, ignored by git). Failing examples are collected (not shrunk)
and the test fails at the end listing the first few with their damage, command and output.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import shutil
import signal
import tempfile
import time
from collections import Counter
from datetime import timedelta
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aogm_cli.cli import main
from aogm_cli.io.detectorfile import default_detector_path

EXAMPLES = int(os.environ.get("AOGM_FUZZ_EXAMPLES", "15"))
HANG_SECONDS = float(os.environ.get("AOGM_FUZZ_HANG_SECONDS", "30"))
# The header walk's limit in the children (the product's default is 20 s): a damaged header that
# makes the HDF5 library spin is refused after this long, so that it does not dominate the run.
WATCHDOG_SECONDS = os.environ.get("AOGM_FUZZ_WATCHDOG_SECONDS", "3")
WORLDS = sorted((Path(__file__).resolve().parent.parent / "worlds").glob("*.yaml"))
BUDGET = ["--max-work", "3e5", "--max-memory", "256M"]  # every bundled world fits (<= 2.7e5 ray casts)
MAP_BUDGET = ["--max-work", "1e8", "--max-memory", "512M"]

SETTINGS = settings(
    max_examples=EXAMPLES,
    derandomize=True,
    database=None,
    deadline=timedelta(seconds=HANG_SECONDS + 10),  # the child is stopped at HANG_SECONDS (a hang)
    suppress_health_check=list(HealthCheck),
    print_blob=False,
)

# --- running one command: a forked child, a hard time limit -------------------------------------


def run_guarded(args: list[str], folder: Path) -> dict:
    """``aogm ARGS`` in a forked child with CliRunner: {"exit", "output", "seconds", "signal"};
    exit None when the child was stopped after HANG_SECONDS or died of a signal."""
    report = folder / "result.json"
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        code = 0
        os.environ["AOGM_HDF5_WATCHDOG_SECONDS"] = WATCHDOG_SECONDS
        try:
            result = CliRunner().invoke(main, [str(a) for a in args])
            text = result.output
            if result.exception is not None and not isinstance(result.exception, SystemExit):
                text += f"\n[uncaught {result.exception.__class__.__name__}: {result.exception}]"
            report.write_text(json.dumps({"exit": result.exit_code, "output": text}))
        except BaseException as exc:  # noqa: BLE001
            report.write_text(json.dumps({"exit": -1, "output": f"[runner failed: {exc!r}]"}))
            code = 3
        os._exit(code)
    deadline = t0 + HANG_SECONDS
    status = None
    while True:
        done, raw = os.waitpid(pid, os.WNOHANG)
        if done:
            status = os.waitstatus_to_exitcode(raw)
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            break
        time.sleep(0.002)
    seconds = time.monotonic() - t0
    if status is None:
        return {"exit": None, "output": "", "seconds": seconds, "signal": "hang"}
    if status < 0 or not report.exists():
        return {"exit": None, "output": "", "seconds": seconds, "signal": f"died (status {status})"}
    out = json.loads(report.read_text())
    report.unlink()
    return {**out, "seconds": seconds, "signal": None}


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --- the tally of one file kind -----------------------------------------------------------------


class Tally:
    """Counts of one file kind's outcomes, and the first failing examples."""

    def __init__(self, kind: str):
        self.kind = kind
        self.counts: Counter = Counter()
        self.failures: list[str] = []
        self.slowest = 0.0
        self.t0 = time.monotonic()
        self.capsys = None
        self.watchdog: list[str] = []

    def check(self, damage: str, args: list[str], damaged: Path, before: str, outputs: list[Path], folder: Path):
        result = run_guarded(args, folder)
        self.counts["examples"] += 1
        self.slowest = max(self.slowest, result["seconds"])
        code, text = result["exit"], result["output"]
        problems = []
        if result["signal"] == "hang":
            self.counts["hangs"] += 1
            problems.append(f"hang: no end within {HANG_SECONDS:g} s")
        elif result["signal"] is not None:
            self.counts["crashes"] += 1
            problems.append(f"crash: child {result['signal']}")
        elif code == 1 or "Traceback" in text or "aogm: failed:" in text or "[uncaught" in text:
            self.counts["crashes"] += 1
            problems.append(f"crash: exit {code}")
        elif code not in (0, 2):
            self.counts["other_exits"] += 1
            problems.append(f"exit {code}")
        else:
            self.counts[f"exit_{code}"] += 1
            if "did not finish in" in text:
                self.counts["watchdog"] += 1
                if len(self.watchdog) < 3:
                    self.watchdog.append(f"    {damage}: {result['seconds']:.1f} s")
            if code == 2 and str(damaged) not in text:
                self.counts["unnamed"] += 1
                problems.append("exit 2 without the file's name")
        if result["signal"] is None and code != 0:
            partial = [p.name for p in outputs if p.exists()]
        else:
            partial = []
        partial += [p.name for p in folder.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")]
        if partial:
            self.counts["partial_outputs"] += 1
            problems.append(f"left behind: {partial}")
        if damaged.exists() and digest(damaged) != before:
            self.counts["input_changed"] += 1
            problems.append("the input changed")
        if problems:
            self.counts["failing"] += 1
            if len(self.failures) < 10:
                lines = text.strip().splitlines()
                self.failures.append(f"{'; '.join(problems)}\n    damage: {damage}\n    command: aogm "
                                     f"{' '.join(map(str, args))}\n    output: {' | '.join(lines[-4:])[:600]}")
        for p in outputs:  # the next example starts clean
            if p.exists():
                p.unlink()

    def finish(self):
        took = time.monotonic() - self.t0
        c = self.counts
        line = (f"fuzz {self.kind:9s}: {c['examples']} examples, {c['crashes']} crashes, {c['hangs']} hangs, "
                f"{c['other_exits']} other exits, {c['partial_outputs']} partial outputs, "
                f"{c['input_changed']} inputs changed, {c['unnamed']} unnamed refusals "
                f"(exit 0: {c['exit_0']}, exit 2: {c['exit_2']}, of which {c['watchdog']} by the header walk's {WATCHDOG_SECONDS} s limit); slowest {self.slowest:.1f} s, {took:.1f} s in all")
        with self.capsys.disabled():
            print("\n" + line, flush=True)
            if self.watchdog:
                print("  refused by the header walk's limit (the first few):\n" + "\n".join(self.watchdog), flush=True)
        assert not self.failures, line + "\n" + "\n".join(self.failures)


@pytest.fixture
def tally(request, capsys):
    """The test's Tally; ``tally.finish()`` at the test's end prints the counts (shown even without
    ``-s``) and fails the test on any failing example."""
    t = Tally(request.node.name.removeprefix("test_fuzz_"))
    t.capsys = capsys
    return t


# --- worlds ---------------------------------------------------------------------------------------

BAD_VALUES = [None, "", "x", "1.0", [], {}, [[]], True, False, 0, 0.0, -1, -1.5, 1e-300, 1e300, 10**30, -10**30,
              math.nan, math.inf, -math.inf, [1, 2], [math.nan, 0], [[0, 0], [math.inf, 1]], {"a": 1},
              list(range(50)), "\x00", "é" * 3]


def paths(value, prefix=()):
    """Every path into a YAML tree (tuples of keys and indexes), the root included."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from paths(v, prefix + (i,))


def locate(tree, path):
    for k in path:
        tree = tree[k]
    return tree


@st.composite
def tree_edit(draw, tree):
    """One edit of ``tree`` in place; its description."""
    all_paths = [p for p in paths(tree) if p]
    path = draw(st.sampled_from(all_paths))
    node = locate(tree, path)
    parent = locate(tree, path[:-1]) if path else None
    ops = ["replace", "scale", "add_key", "delete", "truncate", "duplicate"]
    op = draw(st.sampled_from(ops))
    where = ".".join(map(str, path)) or "(root)"
    if op == "delete" and path:
        del parent[path[-1]]
        return f"delete {where}"
    if op == "add_key" and isinstance(node, dict):
        key = draw(st.sampled_from(["unknown", "extra_key", "x", "1", "walls", "sonar", "errors"]))
        node[key] = copy.deepcopy(draw(st.sampled_from(BAD_VALUES)))  # later edits must not change BAD_VALUES
        return f"add {where}.{key}"
    if op == "truncate" and isinstance(node, list):
        n = draw(st.integers(0, max(0, len(node) - 1)))
        del node[n:]
        return f"truncate {where} to {n}"
    if op == "duplicate" and isinstance(node, list) and node:
        node.extend(copy.deepcopy(node) * draw(st.integers(1, 3)))
        return f"duplicate {where}"
    if op == "scale" and isinstance(node, (int, float)) and not isinstance(node, bool) and path:
        factor = draw(st.sampled_from([0, -1, 1e-6, 1e6, 1e12, 0.5, 2, 100]))
        parent[path[-1]] = node * factor
        return f"scale {where} by {factor:g}"
    value = copy.deepcopy(draw(st.one_of(st.sampled_from(BAD_VALUES),
                                         st.floats(allow_nan=True, allow_infinity=True),
                                         st.integers(-10**6, 10**6), st.text(max_size=8))))
    parent[path[-1]] = value
    return f"replace {where} with {value!r}"


@st.composite
def byte_edit(draw, data: bytes):
    """One byte-level edit of ``data``: flip, zero or overwrite a run, truncate, insert or append."""
    data = bytearray(data)
    n = len(data)
    op = draw(st.sampled_from(["flip", "zero", "overwrite", "truncate", "insert", "append"]))
    at = draw(st.integers(0, max(0, n - 1)))
    length = draw(st.integers(1, 64))
    if op == "flip":
        mask = draw(st.sampled_from([0xFF, 0x80, 0x01, 0x20]))
        data[at:at + length] = bytes(b ^ mask for b in data[at:at + length])
    elif op == "zero":
        data[at:at + length] = bytes(len(data[at:at + length]))
    elif op == "overwrite":
        data[at:at + length] = draw(st.binary(min_size=len(data[at:at + length]), max_size=len(data[at:at + length])))
    elif op == "truncate":
        del data[at:]
    elif op == "insert":
        data[at:at] = draw(st.sampled_from([b"\t", b"\x00", b"\xef\xbb\xbf", b"\xff\xfe", b": ", b"- ", b"[", b"{",
                                            b"&a *a", b"!!python/object:os.system", b"\n  ", b"%YAML 9\n"]))
    else:
        data += draw(st.binary(min_size=1, max_size=length))
    return bytes(data), f"{op} at {at} ({length})"


def world_texts():
    texts = {w.name: w.read_text() for w in WORLDS}

    @st.composite
    def mutated(draw):
        name = draw(st.sampled_from(sorted(texts)))
        tree = yaml.safe_load(texts[name])
        edits = [draw(tree_edit(tree)) for _ in range(draw(st.integers(0, 3)))]
        text = yaml.safe_dump(tree, allow_unicode=True, sort_keys=False).encode()
        for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2]))):
            text, what = draw(byte_edit(text))
            edits.append("bytes: " + what)
        if not edits:
            edits = ["unchanged"]
        return name, text, edits

    return mutated()


def test_fuzz_worlds(tally):
    @SETTINGS
    @given(world_texts())
    def fuzz(example):
        name, text, edits = example
        with tempfile.TemporaryDirectory(prefix="aogm-fuzz-") as d:
            folder = Path(d)
            world = folder / name
            world.write_bytes(text)
            out = folder / "log.h5"
            args = ["simulate", world, "-o", out, "-q", *BUDGET]
            tally.check(f"{name}: {'; '.join(edits)}", args, world, digest(world), [out], folder)

    fuzz()
    tally.finish()


# --- HDF5 files ----------------------------------------------------------------------------------

TINY_WORLD = """\
name: tiny
bounds: [0, 0, 2, 2]
truth_resolution: 0.05
walls:
  - points: [[0.1, 0.1], [1.9, 0.1], [1.9, 1.9], [0.1, 1.9], [0.1, 0.1]]
boxes:
  - {center: [1.4, 1.4], size: [0.3, 0.2]}
robot: {radius: 0.1}
trajectory:
  poses: [[0.8, 0.8, 0], [0.9, 0.8, 20], [1.0, 0.85, 40], [1.0, 0.9, 90]]
sonar: {count: 8, max_range: 2.0, sub_rays: 5}
checks:
  - name: middle
    passable: {from: [0.6, 0.6], to: [1.0, 1.0], robot_radius: 0.1}
"""


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """A tiny valid log, its standard map and the packaged detector; every mode run once here so
    that the forked children find the kernels compiled."""
    folder = tmp_path_factory.mktemp("fuzz_good")
    (folder / "tiny.yaml").write_text(TINY_WORLD)
    runner = CliRunner()

    def ok(*args):
        result = runner.invoke(main, [str(a) for a in args])
        assert result.exit_code == 0, result.output

    ok("simulate", folder / "tiny.yaml", "-o", folder / "log.h5", "-q", "--seed", "1")
    ok("map", folder / "log.h5", "--mode", "standard", "-o", folder / "map.h5", "-q")
    ok("map", folder / "log.h5", "--mode", "em", "-o", folder / "em.h5", "-q")
    ok("map", folder / "log.h5", "--mode", "adaptive", "-o", folder / "ad.h5", "-q")
    ok("render", folder / "map.h5", "-o", folder / "map.png")
    shutil.copy(default_detector_path(), folder / "detector.h5")
    with tempfile.TemporaryDirectory() as d:  # a world, to warm up the simulator's kernels
        ok("simulate", WORLDS[0], "-o", Path(d) / "w.h5", "-q")
    return folder


def h5_objects(file: Path) -> tuple[list[str], list[tuple[str, str]]]:
    """The datasets and groups, and the (object, attribute) pairs, of ``file``."""
    objects = ["/"]
    with h5py.File(file, "r") as f:
        attrs = [("/", k) for k in f.attrs]

        def visit(name, obj):
            objects.append(name)
            attrs.extend((name, k) for k in obj.attrs)

        f.visititems(visit)
    return objects, attrs


BAD_ATTRS = ["", "x", "{", "[]", "{}", '{"a": 1}', b"\xff\xfe", 0, -1, 3, 10**12, 0.0, -1e300, 1e300, np.nan, np.inf,
             -np.inf, True, np.array([1.0, 2.0, 3.0]), np.array([np.nan, 0.0]), np.zeros((2, 2)), np.array([b"a", b"b"])]


@st.composite
def h5_edit(draw, objects, attrs):
    """An edit made through h5py: a function of the open file, and its description."""
    op = draw(st.sampled_from(["del_attr", "set_attr", "set_attr", "del_object", "dtype", "shape", "values",
                               "values", "to_group"]))
    datasets = [o for o in objects if o != "/"]
    if op in ("del_attr", "set_attr") and attrs:
        obj, key = draw(st.sampled_from(attrs))
        if op == "del_attr":
            return (lambda f: f[obj].attrs.__delitem__(key)), f"delete attribute {obj}.{key}"
        value = draw(st.sampled_from(BAD_ATTRS))
        return (lambda f: f[obj].attrs.__setitem__(key, value)), f"set attribute {obj}.{key} = {value!r}"
    if not datasets:
        return (lambda f: None), "noop"
    name = draw(st.sampled_from(datasets))
    if op == "del_object":
        return (lambda f: f.__delitem__(name)), f"delete {name}"
    if op == "to_group":
        def to_group(f):
            del f[name]
            f.create_group(name)
        return to_group, f"{name} replaced by a group"
    dtype = draw(st.sampled_from(["int8", "uint8", "int64", "float16", "float32", "float64", "bool", "complex64",
                                  "S4"]))
    shape_op = draw(st.sampled_from(["empty", "scalar", "drop_row", "add_axis", "transpose", "flat", "huge_1d"]))
    fill = draw(st.sampled_from([np.nan, np.inf, -np.inf, -1.0, 0.0, 1.0, 2.0, 1e30, -1e30, 255.0, 7.0]))
    frac = draw(st.floats(0.0, 1.0))

    def edit(f):
        obj = f.get(name)
        if not isinstance(obj, h5py.Dataset):
            return
        data = obj[()]
        attributes = dict(obj.attrs)
        if op == "dtype":
            try:
                data = np.asarray(data).astype(dtype)
            except (ValueError, TypeError, OverflowError):
                data = np.zeros(np.shape(data), dtype=dtype)
        elif op == "shape":
            data = np.asarray(data)
            if shape_op == "empty":
                data = data[:0]
            elif shape_op == "scalar":
                data = data.reshape(-1)[:1].reshape(()) if data.size else np.float64(0)
            elif shape_op == "drop_row":
                data = data[:-1]
            elif shape_op == "add_axis":
                data = data[..., None]
            elif shape_op == "transpose":
                data = data.T.copy()
            elif shape_op == "flat":
                data = data.reshape(-1)
            else:
                data = np.zeros(200_000, dtype=data.dtype if data.dtype.kind in "biuf" else np.float64)
        else:
            data = np.array(data, copy=True)
            if data.dtype.kind in "fc" and data.size:
                flat = data.reshape(-1)
                flat[: max(1, int(frac * flat.size))] = fill
            elif data.dtype.kind in "iub" and data.size:
                flat = data.reshape(-1)
                if data.dtype.kind == "b":
                    value = True
                else:
                    info = np.iinfo(data.dtype)
                    value = info.max if not math.isfinite(fill) else int(np.clip(fill, info.min, info.max))
                flat[: max(1, int(frac * flat.size))] = value
        del f[name]
        f.create_dataset(name, data=data)
        for k, v in attributes.items():
            f[name].attrs[k] = v

    what = {"dtype": f"{name} as {dtype}", "shape": f"{name} reshaped ({shape_op})",
            "values": f"{name}: first {frac:.0%} set to {fill}"}[op]
    return edit, what


INTERESTING = [0, 8, 16, 24, 32, 512, 520, 540, 560, 600, 700, 800, 1024, 1400, 2048, 3000, 4096]


@st.composite
def h5_damage(draw, file: Path):
    """The damaged bytes of ``file``: raw byte edits, or edits through h5py (which leave the seal
    broken, so that the reader walks the headers), or both."""
    data = file.read_bytes()
    how = draw(st.sampled_from(["bytes", "bytes", "h5py", "h5py", "both"]))
    edits = []
    if how in ("h5py", "both"):
        objects, attrs = h5_objects(file)
        changes = [draw(h5_edit(objects, attrs)) for _ in range(draw(st.integers(1, 3)))]
        with tempfile.TemporaryDirectory() as d:
            copy_ = Path(d) / "x.h5"
            copy_.write_bytes(data)
            with h5py.File(copy_, "a") as f:
                for change, what in changes:
                    try:
                        change(f)
                    except (KeyError, ValueError, TypeError, OSError, RuntimeError) as exc:
                        what += f" (not applied: {exc.__class__.__name__})"
                    edits.append(what)
            data = copy_.read_bytes()
    if how in ("bytes", "both"):
        n = len(data)
        for _ in range(draw(st.integers(1, 4))):
            op = draw(st.sampled_from(["flip", "zero", "overwrite", "truncate", "append", "flip", "zero", "overwrite"]))
            at = draw(st.one_of(st.sampled_from([i for i in INTERESTING if i < n] + [n - 1, n // 2]),
                                st.integers(0, n - 1)))
            length = draw(st.sampled_from([1, 2, 4, 8, 16, 64, 300]))
            buf = bytearray(data)
            if op == "flip":
                mask = draw(st.integers(1, 255))
                buf[at:at + length] = bytes(b ^ mask for b in buf[at:at + length])
            elif op == "zero":
                buf[at:at + length] = bytes(len(buf[at:at + length]))
            elif op == "overwrite":
                k = len(buf[at:at + length])
                buf[at:at + length] = draw(st.binary(min_size=k, max_size=k))
            elif op == "truncate":
                del buf[at:]
            else:
                buf += draw(st.binary(min_size=1, max_size=length))
            data = bytes(buf)
            edits.append(f"{op} {length} at {at}" + (f" (xor {mask:#04x})" if op == "flip" else ""))
    return data, edits


def h5_test(kind: str, good: Path, tally: Tally):
    source = {"log": "log.h5", "map": "map.h5", "detector": "detector.h5"}[kind]

    @SETTINGS
    @given(h5_damage(good / source), st.sampled_from(["standard", "standard", "standard", "em"]))
    def fuzz(damage, mode):
        data, edits = damage
        with tempfile.TemporaryDirectory(prefix="aogm-fuzz-") as d:
            folder = Path(d)
            bad = folder / f"bad_{source}"
            bad.write_bytes(data)
            if kind == "log":
                out = folder / "map_out.h5"
                args = ["map", bad, "--mode", mode, "-o", out, "-q", *MAP_BUDGET]
            elif kind == "map":
                out = folder / "out.png"
                args = ["render", bad, "-o", out, "-q"]
            else:
                out = folder / "map_out.h5"
                args = ["map", good / "log.h5", "--mode", "adaptive", "--detector", bad, "-o", out, "-q", *MAP_BUDGET]
            tally.check("; ".join(edits), args, bad, digest(bad), [out], folder)

    fuzz()
    tally.finish()


def test_fuzz_logs(good, tally):
    h5_test("log", good, tally)


def test_fuzz_maps(good, tally):
    h5_test("map", good, tally)


def test_fuzz_detectors(good, tally):
    h5_test("detector", good, tally)

"""A full disk while writing (RLIMIT_FSIZE in the child): exit 1 naming the file, no temporary, no
output, inputs untouched; one failing write of several leaves none (all or nothing); stale
temporaries of a killed run are removed by the next.
"""

from __future__ import annotations

import hashlib
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

import aogm_cli.io.atomic as atomic
from aogm_cli.cli import main
from aogm_cli.core.errors import OutputError

ROOT = Path(__file__).resolve().parent.parent
WORLD = ROOT / "worlds" / "corridor_door.yaml"
LIMIT = 4096  # bytes: smaller than any log, map, detector or PNG written below


def _limited():
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # write() then fails with EFBIG instead of a kill
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, LIMIT))


def run_full(args, cwd) -> subprocess.CompletedProcess:
    # no bytecode written by the limited child: Python's own write of a .pyc is cut at LIMIT bytes
    # and kept (a short write is no error to it), and every later import of that module fails
    env = os.environ | {"PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.run([sys.executable, "-m", "aogm_cli", *map(str, args)], cwd=cwd, preexec_fn=_limited,
                          capture_output=True, text=True, timeout=300, env=env)


def digest(*paths) -> list[str]:
    return [hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths]


def leftovers(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.name.endswith(".tmp"))


@pytest.fixture(scope="module")
def door(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("disk_full")
    res = CliRunner().invoke(main, ["simulate", str(WORLD), "-o", str(folder / "door.h5"), "-q"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["map", str(folder / "door.h5"), "--mode", "standard", "-o", str(folder / "m.h5"), "-q"])
    assert res.exit_code == 0, res.output
    (folder / "tiny.log").write_text("".join(
        f"FLASER 3 1.0 2.0 3.0 {i * 0.01:.2f} 0 0 0 0 0 {i * 0.1:.1f} h {i * 0.1:.1f}\n" for i in range(200)))
    return folder


def check_failed(res, folder: Path, named: Path, outputs: list[Path]) -> None:
    assert res.returncode == 1, res.stderr
    lines = res.stderr.strip().splitlines()
    assert lines == [f"aogm: error: {named}: file too large"], res.stderr
    assert "Traceback" not in res.stderr
    assert not [p for p in outputs if p.exists()]
    assert leftovers(folder) == []


@pytest.mark.parametrize("command", ["simulate", "map", "compare", "import", "train", "render", "export"])
def test_a_full_disk_is_exit_1_naming_the_file_and_leaves_nothing(door, tmp_path, command):
    inputs = [door / "door.h5", door / "tiny.log", door / "m.h5", WORLD]
    before = digest(*inputs)
    out = tmp_path
    if command == "simulate":
        outputs = [out / "sim.h5", out / "sim.png"]
        args = ["simulate", WORLD, "-o", outputs[0], "--png", outputs[1], "-q"]
    elif command == "map":
        outputs = [out / "m.h5", out / "m.png"]
        args = ["map", door / "door.h5", "--mode", "standard", "-o", outputs[0], "--png", outputs[1], "-q"]
    elif command == "compare":
        outputs = [out / "maps", out / "r.json"]
        args = ["compare", door / "door.h5", "--modes", "standard", "--maps-dir", outputs[0], "--json", outputs[1], "-q"]
    elif command == "import":
        outputs = [out / "tiny.h5"]
        args = ["import", "carmen", door / "tiny.log", "-o", outputs[0], "-q"]
    elif command == "train":
        outputs = [out / "det.h5"]
        args = ["train", door / "door.h5", "-o", outputs[0], "-q"]
    elif command == "render":
        outputs = [out / "r.png"]
        args = ["render", door / "m.h5", "-o", outputs[0], "-q"]
    else:
        outputs = [out / f"e{suffix}" for suffix in (".pgm", ".yaml", ".png", "_scale.yaml")]
        args = ["export", door / "m.h5", "-o", out / "e", "-q"]
    res = run_full(args, tmp_path)
    named = out / "maps" / "door_standard.h5" if command == "compare" else outputs[0]
    check_failed(res, tmp_path, named, outputs)
    assert digest(*inputs) == before


def _fail_on_second_write(monkeypatch):
    real = atomic._write
    calls = []

    def failing(temp, content):
        calls.append(temp)
        if len(calls) == 2:
            raise OSError(28, os.strerror(28))  # ENOSPC
        real(temp, content)

    monkeypatch.setattr(atomic, "_write", failing)
    return calls


def test_map_with_a_failing_png_write_leaves_no_map(door, tmp_path, monkeypatch):
    calls = _fail_on_second_write(monkeypatch)
    m, png = tmp_path / "m.h5", tmp_path / "m.png"
    res = CliRunner().invoke(main, ["map", str(door / "door.h5"), "--mode", "standard", "-o", str(m), "--png", str(png)])
    assert res.exit_code == 1, res.output
    assert f"aogm: error: {png}: no space left on device" in res.output
    assert len(calls) == 2 and not m.exists() and not png.exists() and leftovers(tmp_path) == []


def test_compare_with_a_failing_figure_write_leaves_no_json_and_no_maps(door, tmp_path, monkeypatch):
    _fail_on_second_write(monkeypatch)
    args = ["compare", str(door / "door.h5"), "--modes", "standard", "--json", str(tmp_path / "r.json"),
            "--figure", str(tmp_path / "f.png"), "-q"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1 and "f.png: no space left on device" in res.output
    assert list(tmp_path.iterdir()) == []
    _fail_on_second_write(monkeypatch)
    res = CliRunner().invoke(main, [*args, "--maps-dir", str(tmp_path / "made" / "maps")])
    assert res.exit_code == 1 and "r.json: no space left on device" in res.output
    assert list(tmp_path.iterdir()) == []  # the --maps-dir folders made for the commit are gone again


def test_a_failed_rename_puts_back_the_outputs_already_renamed(tmp_path, monkeypatch):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_bytes(b"old a")
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if Path(dst) == b:
            raise OSError(5, os.strerror(5))
        real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", failing)
    with pytest.raises(OutputError, match="b.txt: input/output error"):
        atomic.write_files_atomically([(a, b"new a"), (b, b"new b")])
    assert a.read_bytes() == b"old a" and not b.exists() and leftovers(tmp_path) == []


def test_stale_temporaries_of_a_killed_run_are_removed_by_the_next(door, tmp_path):
    out = tmp_path / "m.h5"
    args = [sys.executable, "-m", "aogm_cli", "map", str(door / "door.h5"), "--mode", "standard", "-o", str(out), "-q"]
    killed = subprocess.Popen(args, stderr=subprocess.DEVNULL)
    time.sleep(0.3)
    killed.kill()
    killed.wait()
    old = time.time() - 60
    stale = tmp_path / f".m.h5.aogm-{killed.pid}-0123abcd.tmp"  # as that run would have named it
    alive = tmp_path / f".m.h5.aogm-{os.getpid()}-0123abcd.tmp"  # a live writer's
    newer = tmp_path / f".m.h5.aogm-{killed.pid}-4567abcd.tmp"  # not older than the next run's start
    other = tmp_path / f".n.h5.aogm-{killed.pid}-89abcdef.tmp"  # another output's
    for path in (stale, alive, newer, other):
        path.write_bytes(b"partial")
        os.utime(path, (old, old))
    future = time.time() + 3600
    os.utime(newer, (future, future))
    res = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert out.exists() and not stale.exists()
    assert alive.exists() and newer.exists() and other.exists()

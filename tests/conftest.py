"""Fixtures the test modules share: corridor_door simulated once per session, the tiny worlds of the
compare tests, a CSV reader, and ``require``: a test whose ``../shared`` data or dev-extra module is
missing skips, or fails under CI (``CI=true``), where all of it is always there."""

from __future__ import annotations

import csv
import hashlib
import importlib
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import NoReturn

import pytest
from click.testing import CliRunner

from aogm_cli.cli import keep_cone_templates, main

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"  # the third-party data dir beside the clone (README, .ci/run)
TRUE = ("1", "true", "yes", "on")

keep_cone_templates()  # tests that call the library build templates once, as the commands do (io.template_store)


class Require:
    """What a test needs from outside the repository. Missing, the test skips with the reason, or,
    when the environment variable CI is true (CI has all of it), fails with the same reason."""

    def __init__(self, shared_root: Path = SHARED):
        self.shared_root = shared_root

    @staticmethod
    def in_ci() -> bool:
        return os.environ.get("CI", "").strip().lower() in TRUE

    def missing(self, reason: str) -> NoReturn:
        if self.in_ci():
            pytest.fail(f"{reason} (CI={os.environ['CI']}: CI always has it, so this fails instead of skipping)",
                        pytrace=False)
        pytest.skip(reason)

    def shared(self, relative: str | Path) -> Path:
        """The path of ``relative`` under ``../shared``, if it exists."""
        path = self.shared_root / relative
        if not path.exists():
            self.missing(f"shared data not available: {path}")
        return path

    def module(self, name: str) -> ModuleType:
        """The module ``name`` imported (one of the dev extra's: pip install -e '.[dev]')."""
        try:
            return importlib.import_module(name)
        except ImportError as e:
            error = e  # reported outside the handler, without the ImportError's traceback
        self.missing(f"module {name!r} cannot be imported ({error}): pip install -e '.[dev]'")


@pytest.fixture(scope="session")
def require() -> Require:
    return Require()


def _state(path: Path) -> tuple[str, list[str]]:
    return hashlib.sha256(path.read_bytes()).hexdigest(), sorted(p.name for p in path.parent.iterdir())


@pytest.fixture(scope="session")
def corridor_door_log(tmp_path_factory) -> Path:
    """worlds/corridor_door.yaml simulated at seed 1 by ``aogm simulate WORLD -o LOG --seed 1 -q``
    (``sys.argv`` as the console script sees it, for the provenance), once per session. Read it, never
    change it or write beside it: the session ends with an error if a test did."""
    world = ROOT / "worlds" / "corridor_door.yaml"
    path = tmp_path_factory.mktemp("corridor_door") / "door.h5"
    argv = ["aogm", "simulate", str(world), "-o", str(path), "--seed", "1", "-q"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sys, "argv", argv)
        result = CliRunner().invoke(main, argv[1:])
    assert result.exit_code == 0, result.output
    before = _state(path)
    yield path
    assert _state(path) == before, f"a test changed the shared log {path} or wrote beside it"


TINY_DOOR = """
name: tiny_door
bounds: [-0.5, -0.5, 6.5, 4.0]
truth_resolution: 0.1
walls:
  - points: [[0, 0], [6, 0]]
  - points: [[0, 2], [6, 2]]
    openings: [{at: 3.0, width: 1.0}]
  - points: [[0, 0], [0, 2]]
  - points: [[6, 0], [6, 2]]
  - points: [[2, 2], [2, 3.5], [4, 3.5], [4, 2]]
trajectory:
  waypoints: [[0.5, 1.0], [5.5, 1.0]]
  speed: 0.5
  scan_period: 0.5
sonar: {count: 16, max_range: 4.0}
checks:
  - name: door_passable
    passable: {from: [3.0, 1.0], to: [3.0, 3.0], robot_radius: 0.2}
  - name: through_wall
    passable: {from: [1.0, 1.0], to: [1.0, -0.3], robot_radius: 0.1}
"""

TINY_ROOM = """
name: tiny_room
bounds: [-0.5, -0.5, 4.5, 3.0]
truth_resolution: 0.1
walls:
  - points: [[0, 0], [4, 0], [4, 2.5], [0, 2.5], [0, 0]]
  - points: [[2, 0], [2, 1.0]]
trajectory:
  waypoints: [[0.5, 1.8], [3.5, 1.8]]
  speed: 0.5
  scan_period: 0.25
sonar: {count: 12, max_range: 3.0}
checks:
  - name: across
    passable: {from: [0.5, 1.8], to: [3.5, 1.8], robot_radius: 0.15}
"""


@pytest.fixture(scope="session")
def tiny_door_world() -> str:
    """World-file text: a ~20-scan corridor with a door into a room, and two passable checks."""
    return TINY_DOOR


@pytest.fixture(scope="session")
def tiny_room_world() -> str:
    """World-file text: a 4 x 2.5 m room with a short wall, crossed in 20-40 scans, and one passable check."""
    return TINY_ROOM


@pytest.fixture(scope="session")
def read_csv():
    """``read_csv(path, summary=False)``: (header, rows as dicts keyed by the header) of a CSV file; of ``aogm
    compare --csv`` the rows of each log and mode only (``statistic`` empty), or with ``summary`` the summary's."""

    def read(path, summary: bool = False) -> tuple[list[str], list[dict[str, str]]]:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
        found = [dict(zip(rows[0], row, strict=True)) for row in rows[1:]]
        return rows[0], [r for r in found if bool(r.get("statistic")) == summary]

    return read


# The files whose tests take longest (each 20-50 s of a worker's time: documented commands run as
# subprocesses, signals, full disks, damaged files, a Dask cluster) run first, so that the two
# pytest workers of make test share them from the start instead of one running the last of them
# alone while the other waits.
SLOW_FIRST = ("test_documented_commands.py", "test_interrupts.py", "test_disk_full.py", "test_bad_files.py",
              "test_dask.py", "test_api.py", "test_fuzz.py")


def pytest_collection_modifyitems(items):
    order = {name: i for i, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: order.get(item.path.name, len(SLOW_FIRST)))  # stable: the rest as collected

"""Every command line of README.md and docs/*.md runs: each page's command lines are read from the
page (indented or fenced blocks, continuation lines joined) and run in order in a workspace of their
own, on the smallest input that exercises them: a tiny simulated log where a page names a long one, a
two-worker LocalCluster where it names a cluster, the benchmarks at their smallest size. A line no
page runner covers fails the first test, naming its page and line."""

from __future__ import annotations

import glob
import json
import math
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner

from aogm_cli.cli import main

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
# a line in a code block is a command line when it starts with one of these (or sets a variable)
COMMAND = re.compile(r"^(aogm|make|python|printf|echo) |^[A-Za-z_]\w*=\S+$")


@dataclass(frozen=True)
class Line:
    page: str
    number: int  # 1-based, of the line's first physical line
    text: str  # continuation lines joined

    def __str__(self) -> str:
        return f"{self.page}:{self.number}: {self.text}"


def documented_lines(page: Path) -> list[Line]:
    """The command lines of ``page``: in fenced blocks, and in indented blocks (four spaces after
    a blank line, not a list item's continuation)."""
    lines = page.read_text().splitlines()
    out, fenced, indented, previous_blank = [], False, False, True
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith("```"):
            fenced, i = not fenced, i + 1
            continue
        indented = line.startswith("    ") and (previous_blank or indented)
        previous_blank = not line.strip()
        code = line if fenced else line[4:] if indented else None
        start = i + 1
        while code is not None and code.rstrip().endswith("\\") and i + 1 < len(lines):
            i += 1
            code = code.rstrip()[:-1].rstrip() + " " + lines[i].strip()
        if code is not None and COMMAND.match(code.strip()):
            out.append(Line(page.name, start, code.strip()))
        i += 1
    return out


class Workspace:
    """A folder where one page's lines run in order, as a shell would run them: variables, globs,
    ``> FILE`` redirections of printf and echo, ``aogm`` through click's runner, ``make`` in the
    repository with this workspace's outputs, ``python -c``."""

    def __init__(self, folder: Path, replace: dict[str, str], make_vars: dict[str, str] | None = None,
                 accept: tuple[int, ...] = (0,)):
        self.folder, self.replace, self.make_vars, self.accept = folder, replace, make_vars or {}, accept
        self.variables: dict[str, str] = {}

    def args(self, text: str) -> list[str]:
        for old, new in self.replace.items():
            text = text.replace(old, new)
        for name, value in self.variables.items():
            text = text.replace(f"${name}", value)
        out = []
        for arg in shlex.split(text, comments=True):
            found = sorted(glob.glob(arg, root_dir=self.folder)) if any(c in arg for c in "*?") else []
            out.extend(found or [arg])
        return out

    def run(self, line: Line) -> None:
        args = self.args(line.text)
        if len(args) == 1 and "=" in args[0]:
            name, value = args[0].split("=", 1)
            self.variables[name] = value
        elif args[0] in ("printf", "echo"):
            assert args[-2] == ">", line
            text = args[1].encode().decode("unicode_escape") if args[0] == "printf" else args[1] + "\n"
            (self.folder / args[-1]).write_text(text)
        elif args[0] == "aogm":
            result = CliRunner().invoke(main, args[1:], catch_exceptions=False)
            assert result.exit_code in self.accept, f"{line}\n{result.output[-3000:]}"
        elif args[0] == "make":  # the workspace's variables win (outputs here, the smallest sizes)
            assignments = dict(a.split("=", 1) for a in args[2:] if "=" in a) | self.make_vars
            # -o: the .venv this suite runs in stands as installed (its stamp is not remade)
            done = subprocess.run(["make", "-o", ".venv/.installed-stamp", args[1],
                                   *(f"{k}={v}" for k, v in assignments.items())], cwd=ROOT, capture_output=True,
                                  text=True, timeout=600)
            assert done.returncode == 0, f"{line}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        elif args[0] == "python":
            done = subprocess.run([sys.executable, *args[1:]], cwd=self.folder, capture_output=True, text=True,
                                  timeout=300)
            assert done.returncode == 0, f"{line}\n{done.stderr[-2000:]}"
        else:
            raise AssertionError(f"no way to run {line}")


def tiny_log(folder: Path, name: str, world_text: str, seed: int = 1) -> Path:
    (folder / f"{name}.yaml").write_text(world_text)
    out = folder / f"{name}.h5"
    assert CliRunner().invoke(main, ["simulate", str(folder / f"{name}.yaml"), "-o", str(out), "--seed", str(seed),
                                     "-q"]).exit_code == 0
    return out


# --- each page's runner: what its lines need, prepared in the workspace, and how they are run -------

def run_readme(ws: Workspace, lines: list[Line], tiny: str) -> list[Line]:
    """The quick start runs in tests/test_readme.py (read from the same block); ``make test`` is
    this suite (.ci/run runs it); ``make demo`` runs here on one tiny world."""
    world = ws.folder / "tiny_door.yaml"
    world.write_text(tiny)
    ws.make_vars.update(WORLDS=str(world), OUT=str(ws.folder / "out"))
    ran = []
    for line in lines:
        if line.text.startswith("make demo"):
            ws.run(line)
            assert (ws.folder / "out" / "report.png").is_file() and (ws.folder / "out" / "report.json").is_file()
            ran.append(line)
    return ran


def run_page(ws: Workspace, lines: list[Line]) -> list[Line]:
    for line in lines:
        ws.run(line)
    return lines


def covered_by_other_tests(line: Line) -> bool:
    """README's quick start (tests/test_readme.py runs its block as written) and ``make test`` (the suite)."""
    from test_readme import quick_start

    if line.page != "README.md":
        return False
    return line.text.startswith("make test") or shlex.split(line.text, comments=True) in quick_start()


def test_every_documented_command_line_has_a_runner():
    missing = [str(line) for page in PAGES for line in documented_lines(page)
               if page.name not in PAGE_RUNNERS and not covered_by_other_tests(line)]
    assert not missing, "command lines no test runs:\n" + "\n".join(missing)
    assert "env CI=true make test" in (ROOT / ".ci" / "run").read_text()  # README's `make test` is what CI runs


@pytest.fixture
def workspace(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def lines_of(name: str) -> list[Line]:
    return documented_lines(next(p for p in PAGES if p.name == name))


def test_readme_make_demo(workspace, tiny_door_world):
    ran = run_readme(Workspace(workspace, {}), lines_of("README.md"), tiny_door_world)
    assert [line.text.split()[1] for line in ran] == ["demo"]


def test_commands_page(workspace, tiny_door_world, require):
    """docs/commands.md: its compare lines on two tiny logs in out/, its check line on an imported
    RosAria bag (a gate that fails is a result: exit 1 is accepted, bad input never)."""
    out = workspace / "out"
    out.mkdir()
    tiny_log(out, "corridor_door", tiny_door_world)
    tiny_log(out, "corridor_specular", tiny_door_world, seed=2)
    p3dx_log(workspace, require)
    run_page(Workspace(workspace, {}, accept=(0, 1)), lines_of("commands.md"))
    assert (workspace / "all.csv").is_file()


def p3dx_log(folder: Path, require) -> None:
    """p3dx.h5: a RosAria bag of a simulated log, imported as docs/your-robot.md does."""
    bags(folder, require)
    result = CliRunner().invoke(main, ["import", "rosbag", str(folder / "p3dx.bag"), "--ranges", "/RosAria/sonar",
                                       "--pose", "/RosAria/pose", "--mounts", str(folder / "p3dx.txt"), "-o",
                                       str(folder / "p3dx.h5"), "-q"])
    assert result.exit_code == 0, result.output


def bags(folder: Path, require) -> None:
    """run.bag (a ring of Range topics and tf), run_ros2/ (a LaserScan and odometry, sqlite3),
    p3dx.bag (RosAria) and p3dx.txt (its mounts), of the simulated corridor_door log."""
    require.module("rosbags")
    from test_import_rosbag import write_ring_bag, write_rosaria_bag, write_scan_bag

    from aogm_cli.io.logfile import read_log

    log = read_log(simulated_corridor(folder))
    write_ring_bag(folder / "run.bag", "ros1", log)
    write_scan_bag(folder / "run_ros2", "sqlite3", log)
    write_rosaria_bag(folder / "p3dx.bag", "ros1", log)
    (folder / "p3dx.txt").write_text("".join(f"{x!r} {y!r} {math.degrees(yaw)!r}\n"
                                             for x, y, yaw in log.sensor.mount.tolist()))


def simulated_corridor(folder: Path) -> Path:
    return tiny_log(folder, "sim_corridor", (ROOT / "worlds" / "corridor_door.yaml").read_text())


def test_your_robot_page(workspace, tiny_door_world, require):
    """docs/your-robot.md: the intel and 8-sonar logs of ../shared/data as written, the ROS bag
    lines on bags made from a simulated log, the --forward-model line on a second 8-sonar log."""
    for name in ("carmen/intel-corrected.log.gz", "sonar/udacity_8sonar/measurement.txt"):
        if not (SHARED / "data" / name).is_file():
            require.missing(f"../shared/data/{name} is not there")
    bags(workspace, require)
    ws = Workspace(workspace, {"../shared/": f"{SHARED}/", "--mounts p3dx": f"--mounts {workspace / 'p3dx.txt'}"})
    lines = lines_of("your-robot.md")
    for line in lines:
        if "other.h5" in line.text:  # another log of the same robot: the 8-sonar log again
            shutil.copy(workspace / "udacity.h5", workspace / "other.h5")
        ws.run(line)
    assert (workspace / "udacity_model.yaml").is_file() and (workspace / "other_em.h5").is_file()


def test_cluster_page(workspace, tiny_door_world, require):
    """docs/cluster.md: simulate, train and compare (then --resume) on a two-worker LocalCluster,
    two seeds of a tiny world in place of a hundred of every world."""
    distributed = require.module("distributed")
    (workspace / "worlds").mkdir()
    (workspace / "worlds" / "tiny_door.yaml").write_text(tiny_door_world)
    (workspace / "logs").mkdir()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        ws = Workspace(workspace, {"tcp://10.0.0.5:8786": c.scheduler_address, "/shared/": "", "--seeds 1-100":
                                   "--seeds 1-3"})
        run_page(ws, lines_of("cluster.md"))
    assert (workspace / "detector.h5").is_file() and (workspace / "all.json").is_file()


def test_json_page(workspace, tiny_door_world, require):
    """docs/json.md: the schema check, on a report.json of a tiny log."""
    require.module("jsonschema")
    log = tiny_log(workspace, "door", tiny_door_world)
    assert CliRunner().invoke(main, ["compare", str(log), "--json", "report.json", "-q"]).exit_code == 0
    (workspace / "docs").symlink_to(ROOT / "docs")
    run_page(Workspace(workspace, {}), lines_of("json.md"))


def test_benchmarks_page(workspace):
    """docs/benchmarks.md: make bench-scale at its smallest: one size of 100 scans in the standard
    and em modes (the page skips em at one size), one run of the seed benchmark on corridor_door, here."""
    ws = Workspace(workspace, {}, make_vars={"SCALE_SIZES": "100", "SCALE_MODES": "standard,em", "BENCH_RUNS": "1",
                                             "SEED_ARGS": "--worlds corridor_door",
                                             "OUT": str(workspace / "out")})
    run_page(ws, lines_of("benchmarks.md"))
    assert (workspace / "out" / "bench-scale" / "scale.json").is_file()


def test_comparing_page(workspace):
    """docs/comparing.md: the claims' command at two seeds of each seed world, the aggregate gates (made to hold on
    two seeds) and the baseline against the claims' own JSON (runtimes of tiny maps: any ratio)."""
    ws = Workspace(workspace, {"worlds/": f"{ROOT}/worlds/", "--seeds 1-20": "--seeds 1-2", ">= 0\"": ">= -1\"",
                               "> -0.002": "> -1", "accepted.json": "claims.json", "runtime=1.5": "runtime=1000"})
    run_page(ws, lines_of("comparing.md"))
    doc = json.loads((workspace / "new.json").read_text())
    assert doc["summary"]["all"]["logs"] == 4 and doc["baseline"]["regressions"] == []
    assert "## Summary over logs" in (workspace / "claims.md").read_text()


PAGE_RUNNERS = {"README.md": test_readme_make_demo, "comparing.md": test_comparing_page, "commands.md": test_commands_page,
                "your-robot.md": test_your_robot_page, "cluster.md": test_cluster_page, "json.md": test_json_page,
                "benchmarks.md": test_benchmarks_page}


def test_the_extraction_reads_indented_and_fenced_blocks(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("text\n\n    aogm map a.h5 \\\n      -o b.h5\n    not a command\n\n* item\n\n    aogm check x.h5\n\n"
                    "```\nmake demo\n```\n")
    assert [(line.number, line.text) for line in documented_lines(page)] == [
        (3, "aogm map a.h5 -o b.h5"), (9, "aogm check x.h5"), (12, "make demo")]

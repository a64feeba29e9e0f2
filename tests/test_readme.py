"""The README is short and its links hold: at most 250 lines, its picture at the top, every
relative link in it and in docs/ a file of the repository, and its quick start (a bundled world)
and its robot-log commands run as written."""

import re
import shlex
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.io.logfile import read_log

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_the_readme_is_short_with_its_picture_at_the_top():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 250
    first_section = next(i for i, line in enumerate(lines) if line.startswith("## "))
    assert any("](docs/modes.png)" in line for line in lines[:first_section])
    assert (ROOT / "docs" / "modes.png").stat().st_size > 10_000


def test_every_relative_link_resolves_to_a_file_of_the_repository():
    for page in PAGES:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue
            path = (page.parent / target.split("#", 1)[0]).resolve()
            assert path.is_file(), f"{page.name}: {target}"
            assert ROOT in path.parents, f"{page.name}: {target} lies outside the repository"


def indented_blocks(section: str) -> list[str]:
    """The README section's indented (code) blocks, in order."""
    text = (ROOT / "README.md").read_text().split(section, 1)[1].split("\n## ", 1)[0]
    return [re.sub(r"^    ", "", b, flags=re.M) for b in re.findall(r"(?:^    .*\n)+", text, re.M)]


def commands_of(section: str) -> list[list[str]]:
    """The first indented block of a README section as argument lists (continuation lines joined)."""
    block = indented_blocks(section)[0].replace("\\\n", " ")
    return [shlex.split(line, comments=True) for line in block.splitlines() if line.strip()]


def quick_start() -> list[list[str]]:
    """Every command line the README's two runnable sections hold (the quick start, your robot's log)."""
    return commands_of("## Quick start") + commands_of("## Your own robot's log")


def test_the_quick_start_runs_as_written_on_a_bundled_world(tmp_path, monkeypatch):
    (tmp_path / "worlds").symlink_to(ROOT / "worlds")
    monkeypatch.chdir(tmp_path)
    commands = commands_of("## Quick start")
    assert [c[:2] for c in commands] == [["aogm", "simulate"], ["aogm", "map"], ["aogm", "compare"]]
    for args in commands:
        result = CliRunner().invoke(main, args[1:])
        assert result.exit_code == 0, (args, result.output)
    for name in ("door.h5", "door_truth.png", "door_map.h5", "door_map.png", "report.json", "report.png"):
        assert (tmp_path / name).is_file(), name


def test_the_robot_log_commands_run_as_written(corridor_door_log, tmp_path, monkeypatch):
    # a text log of eight sonars made from a simulated one: time and ranges, time and poses
    log = read_log(corridor_door_log)
    ranges = np.where(np.isfinite(log.ranges[:, :8]), log.ranges[:, :8], 5.0)
    np.savetxt(tmp_path / "ranges.txt", np.column_stack([log.time, ranges]))
    np.savetxt(tmp_path / "poses.txt", np.column_stack([log.time, log.pose]))
    monkeypatch.chdir(tmp_path)
    commands = commands_of("## Your own robot's log")
    assert [c[:2] for c in commands] == [["aogm", "import"], ["aogm", "check"], ["aogm", "map"],
                                         ["echo", "resolution: 0.1"], ["aogm", "compare"]]
    for args in commands:
        if args[0] == "echo":  # echo TEXT > FILE
            (tmp_path / args[-1]).write_text(args[1] + "\n")
            continue
        result = CliRunner().invoke(main, args[1:])
        assert result.exit_code == 0, (args, result.output)
    for name in ("robot.h5", "robot_map.h5", "robot_map.png", "report.json", "report.png"):
        assert (tmp_path / name).is_file(), name


def test_the_readmes_python_lines_run():
    code = indented_blocks("## Quick start")[1]
    assert code.startswith("import aogm_cli")
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)  # noqa: S102
    assert scope["m"].mode == "adaptive"

"""The user docs hold together: every relative link and #anchor in README.md, docs/ and worlds/README.md
resolves (anchors as GitHub slugs headings), and no user page or --help text names a commit hash, an
issue number, a date, "scratch" or "not kept" (docs/decisions/, the record of how choices were made, aside)."""

from __future__ import annotations

import re
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main

ROOT = Path(__file__).resolve().parents[1]
DECISIONS = ROOT / "docs" / "decisions"
LINKED = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), ROOT / "worlds" / "README.md"]
USER_PAGES = [page for page in LINKED if DECISIONS not in page.parents]

FENCE = re.compile(r"^\s*(```|~~~)")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
# what a user page must not name: 7-40 hex digits with a digit and a letter among them (a commit), an issue
# or pull request by number, an ISO date or a written-out one, and the words of a lab notebook
HISTORY = {
    "commit hash": re.compile(r"(?<![\w.-])(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?![\w-])"),
    "issue number": re.compile(r"\b(?:issues?|pull request|PR)\s+#?\d+|(?<![\w&#/])#\d+\b", re.IGNORECASE),
    "date": re.compile(r"\b(?:19|20)\d\d-(?:0[1-9]|1[0-2])(?:-\d\d)?\b|\b(?:January|February|March|April|May|June|"
                       r"July|August|September|October|November|December) (?:\d{1,2},? )?(?:19|20)\d\d\b"),
    "scratch": re.compile(r"\bscratch\b", re.IGNORECASE),
    "not kept": re.compile(r"\bnot\s+kept\b", re.IGNORECASE),
}


def slug(heading: str) -> str:
    """GitHub's anchor of a heading's text: lowercase, punctuation but - and _ removed, spaces to -."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())  # a link's text stays
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def prose_lines(text: str) -> list[tuple[int, str]]:
    """(1-based number, line) of ``text`` outside fenced code blocks."""
    out, fenced = [], False
    for number, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            out.append((number, line))
    return out


def anchors(page: Path) -> set[str]:
    """The anchors of ``page``'s headings, a repeated one with -1, -2, ... as GitHub numbers them."""
    seen: dict[str, int] = {}
    out = set()
    for _, line in prose_lines(page.read_text()):
        heading = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not heading:
            continue
        base = slug(heading.group(1))
        count = seen.get(base, 0)
        seen[base] = count + 1
        out.add(base if count == 0 else f"{base}-{count}")
    return out


def shown(path: Path) -> str:
    return str(path.relative_to(ROOT)) if ROOT in path.parents else path.name


def broken_links(page: Path) -> list[str]:
    """``page``'s relative links whose file does not exist, or whose #anchor is no heading of it."""
    out = []
    for number, line in prose_lines(page.read_text()):
        for target in LINK.findall(re.sub(r"`[^`]*`", "", line)):
            if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
                continue
            path_part, _, anchor = target.partition("#")
            path = (page.parent / path_part).resolve() if path_part else page
            where = f"{shown(page)}:{number}: {target}"
            if path_part and (not path.exists() or ROOT not in path.parents):
                out.append(f"{where} (no such file in the repository)")
            elif anchor and path.suffix == ".md" and anchor not in anchors(path):
                out.append(f"{where} (no heading #{anchor} in {shown(path)})")
    return out


def history_in(lines) -> list[str]:
    """Each (where, line) of ``lines`` that names something of HISTORY, with what it names."""
    return [f"{where}: {name}: {line.strip()}" for where, line in lines for name, pattern in HISTORY.items()
            if pattern.search(line)]


@pytest.mark.parametrize("page", LINKED, ids=lambda page: str(page.relative_to(ROOT)))
def test_every_relative_link_and_anchor_resolves(page):
    assert not broken_links(page), "\n".join(broken_links(page))


@pytest.mark.parametrize("page", USER_PAGES, ids=lambda page: str(page.relative_to(ROOT)))
def test_a_user_page_names_no_commit_issue_date_or_lab_note(page):
    lines = [(f"{page.relative_to(ROOT)}:{number}", line) for number, line in enumerate(page.read_text().splitlines(), 1)]
    found = history_in(lines)
    assert not found, "\n".join(found)


def command_paths(command: click.Command, path: tuple[str, ...] = ()):
    """Every command and subcommand of ``command``, as its argument path."""
    yield path
    if isinstance(command, click.Group):
        context = click.Context(command)
        for name in command.list_commands(context):
            yield from command_paths(command.get_command(context, name), (*path, name))


HELP = {" ".join(path) or "aogm": CliRunner().invoke(main, [*path, "--help"], terminal_width=100)
        for path in command_paths(main)}


def test_every_help_text_is_there_and_names_no_commit_issue_date_or_lab_note():
    assert {"aogm", "map", "compare", "calibrate", "import text"} <= set(HELP)
    assert all(result.exit_code == 0 for result in HELP.values())
    lines = [(f"aogm {name} --help:{number}", line) for name, result in HELP.items()
             for number, line in enumerate(result.output.splitlines(), 1)]
    found = history_in(lines)
    assert not found, "\n".join(found)


def test_every_page_and_section_a_help_text_points_to_exists():
    wrong = []
    for name, result in HELP.items():
        text = " ".join(result.output.split())  # a pointer may be wrapped over two lines
        assert "README" not in text, f"aogm {name} --help points into the README"
        for page, section in re.findall(r"(docs/[\w/]+\.md)(?:, \"([^\"]+)\")?", text):
            if not (ROOT / page).is_file():
                wrong.append(f"aogm {name} --help: {page}")
            elif section and slug(section) not in anchors(ROOT / page):
                wrong.append(f"aogm {name} --help: {page}, \"{section}\"")
    assert not wrong, "\n".join(wrong)


def test_the_slugs_and_patterns_are_githubs_and_strict(tmp_path):
    assert slug("`aogm map LOG.h5 --mode standard|em|adaptive -o MAP.h5`") == \
        "aogm-map-logh5---mode-standardemadaptive--o-maph5"
    assert slug("Calibration's constants") == "calibrations-constants"
    page = tmp_path / "p.md"
    page.write_text("# A\n\n## A\n\n```\n# not a heading\n```\n\n[x](#a-1) [y](#a-2) `[c](#c)`\n"
                    "[z](docs/no_such_page.md) [w](https://example.org/#x)\n")
    assert anchors(page) == {"a", "a-1"}
    assert broken_links(page) == ["p.md:9: #a-2 (no heading #a-2 in p.md)",
                                  "p.md:10: docs/no_such_page.md (no such file in the repository)"]
    bad = ["measured at 2d2dfa4", "(issue 47)", "see #28", "on 2026-12-05", "December 5, 2026", "on scratch code",
           "tried and not kept"]
    good = ["a deadbeef or decade word", "0.15000000596", "1e-6 and 2.6e-7", "sha256 " + "ab" * 32,
            "Feng 1996", "[link](#metrics)", "scratch_bytes", "2008-2012", "sigma 0.0586 (+17%)"]
    assert [len(history_in([("x", line)])) for line in bad] == [1] * len(bad)
    assert history_in([("x", line) for line in good]) == []

"""bench/ holds benchmarks only: at most 14 files, each run by a make target or named in
docs/benchmarks.md, and neither the package nor the tests import one of them."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"


def bench_files() -> list[Path]:
    return sorted(p for p in BENCH.iterdir() if p.is_file())


def test_bench_holds_at_most_14_python_files():
    files = bench_files()
    assert [p.name for p in files if p.suffix != ".py"] == []
    assert 0 < len(files) <= 14, [p.name for p in files]


def test_every_bench_script_is_run_by_make_or_named_in_the_benchmarks_page():
    makefile = (ROOT / "Makefile").read_text()
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    run_by_make = set(re.findall(r"bench/(\w+\.py)", makefile))
    named = set(re.findall(r"`(?:python )?(?:bench/)?(\w+\.py)", page))
    missing = [p.name for p in bench_files() if p.name not in run_by_make | named]
    assert missing == []


def test_the_benchmarks_page_names_no_script_that_is_gone():
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    gone = [name for name in set(re.findall(r"bench/(\w+\.py)", page)) if not (BENCH / name).is_file()]
    assert gone == []


def test_neither_the_package_nor_the_tests_import_a_bench_script():
    names = "|".join(p.stem for p in bench_files())
    importing = re.compile(rf"^\s*(from|import)\s+(bench\b|({names})\b)", re.MULTILINE)
    offenders = [str(p.relative_to(ROOT)) for folder in ("aogm_cli", "tests") for p in (ROOT / folder).rglob("*.py")
                 if importing.search(p.read_text())]
    assert offenders == []

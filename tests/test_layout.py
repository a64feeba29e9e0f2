"""The package's layout: the layers of pyproject.toml hold (import-linter), docs/layout.md's layout
tables name exactly those layers in that order, and every package and module is in one of them."""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "aogm_cli"


def contracts() -> dict[str, dict]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    return {c["id"]: c for c in config["contracts"]}


def layer_names(contract: dict) -> list[str]:
    """The contract's layers from the bottom up, siblings of one layer in their written order."""
    return [name.strip() for layer in reversed(contract["layers"]) for name in layer.split("|")]


def readme_rows(heading: str, prefix: str) -> list[str]:
    """The names in the first column of the docs/layout.md table under ``heading`` (``prefix`` stripped)."""
    text = (ROOT / "docs" / "layout.md").read_text()
    section = text.split(heading, 1)[1].split("\n#", 1)[0]
    return [m.group(1) for m in re.finditer(rf"^\| `{re.escape(prefix)}([\w]+)(?:/|\.py)?` \|", section, re.M)]


def test_the_readme_layout_tables_follow_the_layers():
    assert readme_rows("## Layout", "aogm_cli/") == layer_names(contracts()["flow"])
    assert readme_rows("### Inside mapping", "aogm_cli/mapping/") == layer_names(contracts()["modes"])


def test_every_package_and_mapping_module_sits_in_a_layer():
    packages = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}
    modules = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__", "__main__"}  # api.py: aogm from Python
    assert packages | modules == set(layer_names(contracts()["flow"]))
    loose = modules - set(layer_names(contracts()["flow"]))
    assert not loose, f"modules loose at the package root: {sorted(loose)}"
    mapping = {p.stem for p in (PACKAGE / "mapping").glob("*.py")} - {"__init__"}
    mapping |= {p.name for p in (PACKAGE / "mapping").iterdir() if (p / "__init__.py").exists()}
    assert mapping == set(layer_names(contracts()["modes"]))


def test_every_module_says_what_it_owns():
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text().lstrip()
        assert text.startswith('"""'), f"{path.relative_to(ROOT)} has no module docstring"


def test_the_import_contracts_are_kept(require):
    linter = Path(sys.executable).parent / "lint-imports"
    if not linter.exists():
        require.missing(f"import-linter is not installed: no {linter} (pip install -e '.[dev]')")
    result = subprocess.run([str(linter), "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:]

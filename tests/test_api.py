"""aogm from Python (``aogm_cli.api``): its doctests, docs/python.md's "From Python" script as written,
the top-level re-exports (loaded on first use) and the checks on keyword parameters."""

import doctest
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import aogm_cli
import aogm_cli.api
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parent.parent


def test_the_api_doctests_pass():
    result = doctest.testmod(aogm_cli.api, optionflags=doctest.ELLIPSIS)
    assert result.attempted >= 20  # every function has examples
    assert result.failed == 0


def test_every_api_function_has_an_example():
    for name in aogm_cli.api.__all__:
        doc = getattr(aogm_cli.api, name).__doc__
        assert doc and "Examples:" in doc and ">>> " in doc, name


def readme_script() -> str:
    section = (ROOT / "docs" / "python.md").read_text().split("\n## From Python\n", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 1
    return blocks[0]


def test_the_readme_from_python_script_runs_as_written(tmp_path):
    (tmp_path / "script.py").write_text(readme_script())
    result = subprocess.run([sys.executable, "script.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    for mode in ("standard", "em", "adaptive"):
        assert re.search(rf"^{mode} +accuracy 0\.\d+ +leak \d\.\d+", result.stdout, re.M), result.stdout
    assert "warnings: []" in result.stdout
    assert (tmp_path / "door.h5").is_file() and (tmp_path / "door_adaptive.h5").is_file()


def test_the_package_reexports_the_api_on_first_use():
    code = ("import sys, aogm_cli; assert 'aogm_cli.api' not in sys.modules; "
            "assert 'numpy' not in sys.modules; f = aogm_cli.map_log; "
            "assert f is sys.modules['aogm_cli.api'].map_log; print(sorted(aogm_cli.__all__))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert set(aogm_cli.api.__all__) <= set(aogm_cli.__all__)
    with pytest.raises(AttributeError):
        aogm_cli.no_such_function  # noqa: B018


def test_keyword_parameters_are_checked():
    from aogm_cli.core.errors import InputError

    with pytest.raises(TypeError, match="unknown mapping parameter 'sigma'"):
        aogm_cli.map_params(sigma=0.05)
    with pytest.raises(TypeError, match="em= takes a dict"):
        aogm_cli.map_params(em=0.05)
    with pytest.raises(InputError):
        aogm_cli.map_params(em={"no_such_key": 1})


def test_a_map_from_a_path_equals_the_map_of_the_log_in_memory(tmp_path):
    log = aogm_cli.simulate(aogm_cli.bundled_world("corridor_door"), seed=3)
    aogm_cli.save_log(log, tmp_path / "door.h5")
    from_file = aogm_cli.map_log(tmp_path / "door.h5", "standard")
    in_memory = aogm_cli.map_log(log, "standard")
    assert (from_file.probability == in_memory.probability).all()
    assert aogm_cli.evaluate(from_file, tmp_path / "door.h5")["accuracy"] == aogm_cli.evaluate(in_memory, log)["accuracy"]
    assert aogm_cli.check(tmp_path / "door.h5").as_dict()["scans"] == log.n_scans


def test_bundled_worlds_travel_in_the_wheel(tmp_path):
    # issue 30: after `pip install .`, outside the checkout, bundled_world() finds a world that
    # simulates. Build the wheel, unpack it, and import the package from there in a fresh process
    wheel_dir = tmp_path / "wheel"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", str(ROOT), "-w", str(wheel_dir)],
                   check=True, cwd=tmp_path, capture_output=True)
    (wheel,) = wheel_dir.glob("aogm-*.whl")
    unpacked = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(unpacked)
    script = ("import aogm_cli, sys; p = aogm_cli.bundled_world('corridor_door'); "
              "assert str(p).startswith(sys.argv[1]), p; print(p)")
    out = subprocess.run([sys.executable, "-c", script, str(unpacked)], check=True, cwd=tmp_path, capture_output=True,
                         text=True, env={**os.environ, "PYTHONPATH": str(unpacked)}).stdout.strip()
    world = Path(out)
    assert world.is_file() and world.read_text() == (ROOT / "worlds" / "corridor_door.yaml").read_text()
    assert load_world(world).name == "corridor_door"  # what `aogm simulate` reads and checks first

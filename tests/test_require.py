"""conftest.py's ``require``: missing ``../shared`` data, a missing module or tool skips a test, and
fails it, naming what is missing, when CI is true; .ci/run runs ``make test`` with CI=true."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MISSING = "data/aogm-test-no-such-file.h5"


@pytest.mark.parametrize("value", ["true", "TRUE", "1", "yes", "on"])
def test_missing_shared_data_fails_under_ci_naming_the_path(require, monkeypatch, tmp_path, value):
    monkeypatch.setattr(require, "shared_root", tmp_path)
    monkeypatch.setenv("CI", value)
    with pytest.raises(pytest.fail.Exception, match=re.escape(str(tmp_path / MISSING))):
        require.shared(MISSING)


@pytest.mark.parametrize("value", [None, "", "false", "0", "no"])
def test_missing_shared_data_skips_outside_ci_naming_the_path(require, monkeypatch, tmp_path, value):
    monkeypatch.setattr(require, "shared_root", tmp_path)
    if value is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", value)
    with pytest.raises(pytest.skip.Exception, match=re.escape(str(tmp_path / MISSING))):
        require.shared(MISSING)


@pytest.mark.parametrize("ci", ["true", "false"])
def test_shared_data_present_is_its_path(require, monkeypatch, tmp_path, ci):
    monkeypatch.setattr(require, "shared_root", tmp_path)
    monkeypatch.setenv("CI", ci)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "x.txt").write_text("x")
    assert require.shared("data/x.txt") == tmp_path / "data" / "x.txt"


def test_the_real_shared_root_is_beside_the_clone(require):
    assert require.shared_root == ROOT.parent / "shared"


def test_a_missing_module_fails_under_ci_and_skips_outside(require, monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="aogm_no_such_module"):
        require.module("aogm_no_such_module")
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception, match="aogm_no_such_module"):
        require.module("aogm_no_such_module")
    monkeypatch.setenv("CI", "true")
    assert require.module("json").dumps([1]) == "[1]"


def test_ci_runs_make_test_with_ci_true():
    script = (ROOT / ".ci" / "run").read_text()
    assert re.search(r"^phase tests env CI=true make test\b", script, re.MULTILINE), "make test runs without CI=true in .ci/run"

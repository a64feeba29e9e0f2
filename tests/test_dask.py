"""Many logs on Dask (issue 16): ``compare`` and ``simulate`` on a two-worker ``LocalCluster`` give what
``--jobs 1`` and one-by-one runs give, bit for bit; a failed task does not stop the others; ``--resume``;
without Dask, ``--scheduler`` names the extra to install."""

import json
import os
import sys

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main

NOOK = """
name: tiny_nook
bounds: [-0.5, -0.5, 5.0, 3.0]
truth_resolution: 0.1
walls:
  - points: [[0, 0], [4.5, 0], [4.5, 2.5], [0, 2.5], [0, 0]]
  - points: [[1.5, 2.5], [1.5, 1.6]]
  - points: [[3.0, 0], [3.0, 0.8]]
trajectory:
  waypoints: [[0.5, 1.2], [4.0, 1.2]]
  speed: 0.5
  scan_period: 0.4
sonar: {count: 12, max_range: 3.0}
"""


def run(*args, env=None):
    return CliRunner().invoke(main, [str(a) for a in args], env=env)


@pytest.fixture(scope="module")
def cluster(require):
    """A two-worker LocalCluster (one thread each, separate processes); its scheduler's address."""
    distributed = require.module("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        yield c.scheduler_address


@pytest.fixture(scope="module")
def worlds(tmp_path_factory, tiny_door_world, tiny_room_world):
    """World files of three tiny worlds (door, room, nook), of 15-40 scans each."""
    folder = tmp_path_factory.mktemp("worlds")
    paths = []
    for name, text in {"door": tiny_door_world, "room": tiny_room_world, "nook": NOOK}.items():
        (folder / f"{name}.yaml").write_text(text)
        paths.append(folder / f"{name}.yaml")
    return paths


@pytest.fixture(scope="module")
def logs(worlds, tmp_path_factory):
    """The three worlds simulated at seed 1 (one call: DIR/<world>_s1.h5)."""
    folder = tmp_path_factory.mktemp("logs")
    result = run("simulate", *worlds, "--seeds", "1", "-o", f"{folder}/", "-q")
    assert result.exit_code == 0, result.output
    return [folder / f"{w.stem}_s1.h5" for w in worlds]


def _comparable(doc):
    """A --json document without what differs between runs (runtimes, provenance)."""
    return [{k: v for k, v in r.items() if k != "runtime_s"} for r in doc["results"]]


def test_cluster_gives_the_metrics_of_one_job(logs, cluster, tmp_path):
    args = ["compare", *logs, "--modes", "standard,em,adaptive", "-q"]
    one = run(*args, "--jobs", 1, "--json", tmp_path / "one.json")
    assert one.exit_code == 0, one.output
    dask = run(*args, "--scheduler", cluster, "--json", tmp_path / "dask.json", "--maps-dir", tmp_path / "maps")
    assert dask.exit_code == 0, dask.output
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("one.json", "dask.json"))
    assert len(a["results"]) == 9
    assert _comparable(a) == _comparable(b)  # metrics, checks, params, learned models: bit for bit
    assert all(r["runtime_s"] > 0 for r in b["results"])  # timed in the worker
    assert len(list((tmp_path / "maps").glob("*.h5"))) == 9


BUNDLED = ("corridor_door", "t_junction", "l_corridor")  # three of the bundled worlds


def test_cluster_gives_the_metrics_of_one_job_on_bundled_worlds(cluster, tmp_path):
    """The issue's check on bundled worlds: every mode, calibration on, bit for bit."""
    worlds = [os.path.join(os.path.dirname(__file__), "..", "worlds", f"{w}.yaml") for w in BUNDLED]
    result = run("simulate", *worlds, "--seeds", "1", "-o", f"{tmp_path}/", "-q")
    assert result.exit_code == 0, result.output
    logs = [tmp_path / f"{w}_s1.h5" for w in BUNDLED]
    args = ["compare", *logs, "--modes", "standard,em,adaptive", "-q"]
    one = run(*args, "--jobs", 1, "--json", tmp_path / "one.json")
    dask = run(*args, "--scheduler", cluster, "--json", tmp_path / "dask.json")
    assert one.exit_code == 0 and dask.exit_code == 0, one.output + dask.output
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("one.json", "dask.json"))
    assert len(a["results"]) == 9 and _comparable(a) == _comparable(b)


def test_holdout_on_the_cluster(logs, cluster, tmp_path):
    args = ["compare", *logs[:2], "--modes", "standard,em", "--holdout", "0.2", "--seed", 3, "-q"]
    one = run(*args, "--json", tmp_path / "one.json")
    dask = run(*args, "--json", tmp_path / "dask.json", env={"AOGM_SCHEDULER": cluster})
    assert one.exit_code == 0 and dask.exit_code == 0, one.output + dask.output
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("one.json", "dask.json"))
    assert _comparable(a) == _comparable(b)
    assert all(r["metrics"]["holdout_readings"] > 0 for r in b["results"])


def damaged(log, path):
    """A copy of ``log`` whose /scans/pose (rewritten gzip-compressed) cannot be decompressed:
    opening it and reading its truth and ranges work, mapping it fails."""
    path.write_bytes(log.read_bytes())
    with h5py.File(path, "r+") as f:
        pose = f["scans/pose"][...]
        del f["scans/pose"]
        d = f.create_dataset("scans/pose", data=pose, chunks=pose.shape, compression="gzip")
        f.flush()
        info = d.id.get_chunk_info(0)
    data = bytearray(path.read_bytes())
    middle = info.byte_offset + info.size // 2
    data[middle:middle + 16] = b"\xff" * 16
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("where", ["cluster", "jobs"])
def test_a_failed_task_is_reported_and_the_others_finish(logs, cluster, tmp_path, where):
    bad = damaged(logs[0], tmp_path / "bad.h5")
    executor = ("--scheduler", cluster) if where == "cluster" else ("--jobs", 2)
    result = run("compare", bad, logs[1], "--modes", "standard,em", *executor, "--json", tmp_path / "r.json",
                 "--maps-dir", tmp_path / "maps", "-q")
    assert result.exit_code == 2, result.output  # every failure was bad input
    assert f"aogm: failed: {bad} (standard)" in result.output and f"aogm: failed: {bad} (em)" in result.output
    assert "/scans/pose" in result.output and "2 task(s) failed" in result.output
    done = json.loads((tmp_path / "r.json").read_text())["results"]
    assert [(r["log"], r["mode"]) for r in done] == [(str(logs[1]), "standard"), (str(logs[1]), "em")]
    assert sorted(p.name for p in (tmp_path / "maps").iterdir()) == ["room_s1_em.h5", "room_s1_standard.h5"]


def _datasets(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[...]) if isinstance(obj, h5py.Dataset) else None)
    return out


def test_simulate_many_on_the_cluster_matches_one_by_one(worlds, cluster, tmp_path):
    result = run("simulate", *worlds[:2], "--seeds", "1-10", "-o", f"{tmp_path / 'many'}/", "--scheduler", cluster, "-q")
    assert result.exit_code == 0, result.output
    files = sorted((tmp_path / "many").iterdir())
    assert [p.name for p in files] == sorted(f"{w.stem}_s{s}.h5" for w in worlds[:2] for s in range(1, 11))
    for world in worlds[:2]:
        for seed in (1, 7):
            single = tmp_path / f"{world.stem}_{seed}.h5"
            assert run("simulate", world, "-o", single, "--seed", seed, "-q").exit_code == 0
            a, b = _datasets(single), _datasets(tmp_path / "many" / f"{world.stem}_s{seed}.h5")
            assert a.keys() == b.keys() and len(a) > 3
            for name in a:
                np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert not [p for p in (tmp_path / "many").iterdir() if p.name.startswith(".")]  # no temporaries


def test_simulate_resume_skips_complete_logs_and_redoes_a_truncated_one(worlds, tmp_path):
    out = f"{tmp_path / 'logs'}/"
    assert run("simulate", *worlds[:2], "--seeds", "1-3", "-o", out, "--jobs", 2, "-q").exit_code == 0
    files = sorted((tmp_path / "logs").iterdir())
    before = {p.name: p.stat().st_mtime_ns for p in files}
    truncated = tmp_path / "logs" / "door_s2.h5"
    truncated.write_bytes(truncated.read_bytes()[:5000])
    again = run("simulate", *worlds[:2], "--seeds", "1-3", "-o", out, "--resume")
    assert again.exit_code == 0, again.output
    assert "1 log(s) written" in again.output and "5 already complete" in again.output
    after = {p.name: p.stat().st_mtime_ns for p in sorted((tmp_path / "logs").iterdir())}
    assert {n for n in after if after[n] != before[n]} == {"door_s2.h5"}
    assert _datasets(truncated).keys() == _datasets(files[0]).keys()
    # another seed asked for: that log is not the one there, so it is simulated again
    other = run("simulate", worlds[0], "--seeds", "4", "-o", out, "--resume")
    assert "1 log(s) written" in other.output and "0 already complete" in other.output


def test_compare_resume_takes_complete_maps_and_redoes_a_truncated_one(logs, tmp_path):
    args = ["compare", *logs[:2], "--modes", "standard,em", "--maps-dir", tmp_path / "maps"]
    first = run(*args, "--json", tmp_path / "a.json", "-q")
    assert first.exit_code == 0, first.output
    maps = sorted((tmp_path / "maps").iterdir())
    before = {p.name: p.stat().st_mtime_ns for p in maps}
    broken = tmp_path / "maps" / "door_s1_em.h5"
    broken.write_bytes(broken.read_bytes()[:3000])
    again = run(*args, "--json", tmp_path / "b.json", "--resume")
    assert again.exit_code == 0, again.output
    assert "resume: 3 map(s)" in again.output
    after = {p.name: p.stat().st_mtime_ns for p in sorted((tmp_path / "maps").iterdir())}
    assert {n for n in after if after[n] != before[n]} == {"door_s1_em.h5"}
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert [{k: v for k, v in r.items() if k != "detector"} for r in _comparable(a)] == \
        [{k: v for k, v in r.items() if k != "detector"} for r in _comparable(b)]
    # other parameters: nothing is taken
    other = run(*args, "--no-calibrate", "--resume")
    assert other.exit_code == 0 and "resume: 0 map(s)" in other.output


def test_resume_needs_maps_dir(logs):
    result = run("compare", logs[0], "--modes", "standard", "--resume")
    assert result.exit_code == 2 and "--resume: needs --maps-dir" in result.output


def test_without_dask_scheduler_exits_2_naming_the_extra(logs, worlds, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    result = run("compare", logs[0], "--modes", "standard", "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 2, result.output
    assert "pip install aogm[dask]" in result.output and "--scheduler" in result.output
    result = run("simulate", *worlds, "--seeds", "1-2", "-o", f"{tmp_path / 'x'}/", "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 2 and "pip install aogm[dask]" in result.output
    assert not os.path.exists(tmp_path / "x") or not any((tmp_path / "x").iterdir())


def test_train_reads_a_folder_and_a_glob(tmp_path):
    from aogm_cli.cli.options import expand_log_paths
    from aogm_cli.core.errors import InputError

    for name in ("b_s2.h5", "a_s1.h5", "b_s1.h5", "notes.txt"):
        (tmp_path / name).write_bytes(b"")
    assert expand_log_paths([str(tmp_path)], "LOG.h5") == [str(tmp_path / n) for n in ("a_s1.h5", "b_s1.h5", "b_s2.h5")]
    assert expand_log_paths([f"{tmp_path}/b_s*.h5", str(tmp_path / "b_s1.h5")], "LOG.h5") == [
        str(tmp_path / "b_s1.h5"), str(tmp_path / "b_s2.h5")]
    with pytest.raises(InputError, match="no file matches"):
        expand_log_paths([f"{tmp_path}/c_*.h5"], "LOG.h5")
    result = run("train", f"{tmp_path}/zz*.h5", "-o", tmp_path / "d.h5")
    assert result.exit_code == 2 and "no file matches" in result.output


def test_a_lost_local_worker_fails_its_task_only(logs, tmp_path, monkeypatch):
    from aogm_cli import map_files

    mapper = map_files.map_file

    def dies_on_the_room(path, *args, **kwargs):
        if "room" in str(path):
            os._exit(9)  # the worker is lost (killed, out of memory)
        return mapper(path, *args, **kwargs)

    monkeypatch.setattr(map_files, "map_file", dies_on_the_room)  # forked workers inherit it
    result = run("compare", *logs, "--modes", "standard", "--jobs", 2, "--json", tmp_path / "r.json", "-q")
    assert result.exit_code == 1, result.output  # not bad input
    assert f"aogm: failed: {logs[1]} (standard): BrokenProcessPool" in result.output
    done = json.loads((tmp_path / "r.json").read_text())["results"]
    assert [r["log"] for r in done] == [str(logs[0]), str(logs[2])]


def test_one_executor_per_run(logs, worlds, tmp_path):
    """--jobs N and --scheduler together exit 2 naming --jobs; --scheduler for a single log
    simulated alone exits 2 naming it (AOGM_SCHEDULER alone is ignored there)."""
    both = run("compare", *logs, "--modes", "standard", "--jobs", 2, "--scheduler", "tcp://127.0.0.1:1", "-q")
    assert both.exit_code == 2 and "--jobs" in both.output
    both = run("simulate", *worlds, "-o", f"{tmp_path}/", "--jobs", 2, "--scheduler", "tcp://127.0.0.1:1", "-q")
    assert both.exit_code == 2 and "--jobs" in both.output
    one = run("simulate", worlds[0], "-o", tmp_path / "one.h5", "--scheduler", "tcp://127.0.0.1:1", "-q")
    assert one.exit_code == 2 and "--scheduler" in one.output and not (tmp_path / "one.h5").exists()
    env = run("simulate", worlds[0], "-o", tmp_path / "one.h5", "-q", env={"AOGM_SCHEDULER": "tcp://127.0.0.1:1"})
    assert env.exit_code == 0 and (tmp_path / "one.h5").exists()

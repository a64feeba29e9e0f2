"""A map's plan (``mapping.plan``), decided before its first stage and recorded in the map file and
by ``aogm info``; the runner's check of what each stage reads and writes (``mapping.runner``)."""

import dataclasses
import json
import math

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.mapping.learned import Learned, SensorModel
from aogm_cli.mapping.modes import mode_stages, planned
from aogm_cli.mapping.params import params_from
from aogm_cli.mapping.pipeline import TimedSource
from aogm_cli.mapping.plan import CONE, NARROW_BEAM, OUTSIDE_MARGIN, plan_map
from aogm_cli.mapping.runner import Stage, StageError, lacks, run_stages
from aogm_cli.mapping.state import State
from aogm_cli.sensor_models.exact_inverse import MARGIN

SONAR = SensorSpec(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2]]), "sonar", math.radians(30), 0.0, 3.0, 0.01)
LASER = dataclasses.replace(SONAR, kind="laser", beam_width=math.radians(0.5))
ROBOT = Learned(sensor=SensorModel(0.05, 0.05, 0.9, 0.01), origin="file robot.yaml")  # a robot's model, given


def params(**sections):
    return params_from(sections, None, None)


def test_the_plan_of_each_mode_by_hand():
    """What each plan decides from the mode, the parameters, the sensor and the model given."""
    standard = plan_map("standard", params(), SONAR, 0.1, None)
    assert (standard.sensor, standard.learns, standard.outside, standard.start) == (CONE, (), None, None)
    # a sonar log with no model: EM calibrates every default key on the log; adaptive keeps Elfes' map outside
    em = plan_map("em", params(), SONAR, 0.1, None)
    assert em.calibrates and not em.fits_rates and em.model == "learned from this log"
    assert em.learns == ("sigma", "p_rand", "p_hit", "p_max", "lobe_deg") and em.incidence
    assert em.learns_lobe
    # at em.specular_deg 90 no beam is deflected: the angle of incidence is off
    assert not plan_map("em", params(em={"specular_deg": 90}), SONAR, 0.1, None).incidence
    assert plan_map("em", params(em={"specular_deg": 89.5}), SONAR, 0.1, None).incidence
    assert (em.outside, em.thinning, em.start) == (None, None, "standard")
    adaptive = plan_map("adaptive", params(), SONAR, 0.1, None)
    assert (adaptive.outside, adaptive.thinning, adaptive.start, adaptive.decides) == ("elfes", None, "standard", False)
    # a robot's model given: only the building's part is learned, the thinned map stands outside
    given = plan_map("adaptive", params(), SONAR, 0.1, ROBOT)
    assert given.learns == ("p_max", "lobe_deg") and given.fits_rates and not given.calibrates
    assert (given.model, given.outside, given.thinning) == ("file robot.yaml", "thinned", OUTSIDE_MARGIN)
    assert given.start == "elfes in clusters" and given.decides
    # a model from another map of the same log gives everything
    carried = plan_map("em", params(), SONAR, 0.1, dataclasses.replace(ROBOT, made_by="em"))
    assert carried.learns == () and not carried.fits_rates and not carried.calibrates
    # a laser: no angle of incidence, never thinned
    laser = plan_map("adaptive", params(exact={"thin": True}, adaptive={"outside": "thinned"}), LASER, 0.1, ROBOT)
    assert (laser.sensor, laser.incidence, laser.thinning, laser.learns_lobe) == (
        NARROW_BEAM, False, None, False)  # nor a lobe
    assert plan_map("em", params(calibration={"learn": "sigma,lobe_deg"}), LASER, 0.1, None).learns == (
        "sigma",)  # a ray has no lobe to learn
    assert plan_map("em", params(exact={"thin": True}), SONAR, 0.1, None).thinning == MARGIN
    off = plan_map("em", params(calibration={"enabled": False}), SONAR, 0.1, None)
    assert (off.learns, off.calibrates, off.model) == ((), False, "configured")


def test_each_mode_lists_the_stages_its_plan_asks_for():
    names = [s.name for s in mode_stages(plan_map("standard", params(), SONAR, 0.1, None))]
    assert names == ["set_up", "standard", "view"]
    learned = [s.name for s in mode_stages(plan_map("adaptive", params(), SONAR, 0.1, None))]
    assert "rates" not in learned and "thinning" not in learned and "decided" not in learned
    assert {"detector", "clusters", "calibration", "index", "sweeps"} <= set(learned) and "region" not in learned
    robots = [s.name for s in mode_stages(plan_map("adaptive", params(), SONAR, 0.1, ROBOT))]
    assert {"rates", "thinning", "decided"} <= set(robots) and "calibration" not in robots
    assert "deflections" in [s.name for s in mode_stages(plan_map("em", params(), SONAR, 0.1, None))]
    assert "deflections" not in [s.name for s in mode_stages(plan_map("em", params(), LASER, 0.1, None))]
    at_90 = params(em={"specular_deg": 90})
    assert "deflections" not in [s.name for s in mode_stages(plan_map("em", at_90, SONAR, 0.1, None))]


def _state(fields=None) -> State:
    log = Log(np.zeros(1), np.zeros((1, 3)), np.ones((1, 2), dtype=np.float32), SONAR, source="test")
    stages, state = planned(log, "standard", params(resolution=0.5))
    return state.but(**(fields or {}))


def test_a_stage_reading_a_field_no_stage_wrote_is_refused():
    view = Stage("view", lambda s: s, reads=("standard",), writes=("view",))
    with pytest.raises(StageError, match="'view' reads standard"):
        run_stages((view,), _state())
    optional = Stage("view", lambda s: s, reads=("standard?",))  # "?": may be None
    assert run_stages((optional,), _state())[0].standard is None


def test_a_stage_writing_an_undeclared_field_is_refused():
    sneaky = Stage("standard", lambda s: s.but(standard=1, view=2), writes=("standard",))
    with pytest.raises(StageError, match="'standard' wrote view"):
        run_stages((sneaky,), _state())
    replans = Stage("standard", lambda s: s.but(plan=dataclasses.replace(s.plan, mode="em")))
    with pytest.raises(StageError, match="what it was given"):
        run_stages((replans,), _state())
    declared = Stage("standard", lambda s: s.but(standard=1), writes=("standard",))
    assert run_stages((declared,), _state())[0].standard == 1


def test_a_stage_made_once_runs_again_only_when_taken_away():
    calls = []
    make = Stage("standard", lambda s: calls.append(1) or s.but(standard=len(calls)), writes=("standard",),
                 when=lacks("standard"))
    take = Stage("deflections", lambda s: s.but(standard=None), writes=("standard",))
    state, _ = run_stages((make, make, take, make), _state())
    assert state.standard == 2 and len(calls) == 2


def test_the_plan_is_in_the_map_file_and_in_aogm_info(corridor_door_log, tmp_path):
    out = tmp_path / "adaptive.h5"
    runner = CliRunner()
    result = runner.invoke(main, ["map", str(corridor_door_log), "--mode", "adaptive", "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        plan = json.loads(f.attrs["plan"])
    # the packaged detector carries the ring's model: the building's part learned, the thinned map outside
    assert plan["mode"] == "adaptive" and plan["sensor"] == CONE and plan["outside"] == "thinned"
    assert plan["model"].startswith("carried by the packaged detector") and plan["fits_rates"]
    assert plan["stages"][:3] == ["read", "set_up", "readings"] and plan["stages"][-1] == "view"
    info = runner.invoke(main, ["info", str(out)])
    assert info.exit_code == 0, info.output
    assert "plan (decided before the first stage):" in info.output
    assert "  outside: thinned" in info.output and "read > set_up > readings > standard" in info.output
    # the lobe's record in words, as aogm calibrate prints it; its counts stay in --json
    assert "  lobe: echo rate by angle off the axis" in info.output and "-> the whole cone" in info.output
    assert "chances" not in info.output
    assert json.loads(runner.invoke(main, ["info", str(out), "--json"]).output)["plan"] == plan


def test_the_grid_of_a_plan_is_the_logs():
    """``planned`` puts the plan and the state on the log's grid (its poses' bounds)."""
    log = Log(np.zeros(1), np.zeros((1, 3)), np.ones((1, 2), dtype=np.float32), SONAR, source="test")
    stages, state = planned(log, "em", params(resolution=0.5))
    assert isinstance(state.source, TimedSource) and isinstance(state.grid, GridSpec)
    assert state.plan.stages == tuple(s.name for s in stages) and state.grid.resolution == 0.5


def test_a_robots_model_replaces_the_sensor_keys_configured_and_a_learned_lobe_the_configured_one():
    """``Learned.model``: a robot's model given sets sigma, p_rand, p_hit, p_max; a lobe learned from the log
    replaces the one configured (``map_files.learned_over`` warns of both)."""
    configured = params(em={"sigma": 0.2, "lobe_deg": 12.0, "lobe_range": 5.0}).em.forward
    assert (ROBOT.model(configured).sigma, ROBOT.model(configured).lobe_deg) == (0.05, 12.0)
    learned = dataclasses.replace(ROBOT, lobe_deg=0.0, lobe_range=10.0)
    assert (learned.model(configured).lobe_deg, learned.model(configured).lobe_range) == (0.0, 10.0)
    assert SensorModel.read({"sigma": 0.05, "p_rand": 0.05, "p_hit": 0.9, "p_max": 0.01, "opening_deg": 0.0}) == (
        ROBOT.sensor)  # an older model's opening_deg is not read

"""The options that more than one command takes, each defined once (defaults read from the config
dataclasses; which commands take which: the table below), and the progress bar. Every command checks
its outputs with ``io.outputs.resolve_outputs`` before any work."""

# Option                  commands
# -o/--output             simulate, map, train, render, export (a PREFIX), import carmen, import text, import rosbag
# -q/--quiet              simulate, map, train, render, export, compare, import carmen, import text, import rosbag
# --seed                  simulate, train (below 2**32), compare (--holdout)
# --png                   simulate, map
# --mode / --modes        map / compare (choices from core.occupancy_map.MODES; also --require-checks)
# --params, --detector    map, compare
# --resolution            map, calibrate (check: its own, 0.05 by default); refuse_huge_grids: map, calibrate, compare
# --calibrate/--no-calibrate  map, compare (``calibration.enabled``)
# --max-memory/--max-work simulate, map, compare, calibrate (``budget_options``; ``core.budget``)
# --threads               map, compare, calibrate (``threads_option``: EM's sweeps and parts; ``core.budget.Limits``)
# --jobs/-j, --scheduler  simulate, compare (``core.executors``: a local process pool, a Dask cluster)
# --resume                simulate, compare (--maps-dir): skip outputs already complete and valid
# LOG arguments as a folder or a glob (``expand_log_paths``): train
# --kind, --max-range, --min-range, --beam-width, --noise-sigma   import carmen, text, rosbag (``sensor_options``)

from __future__ import annotations

import math
import sys
from contextlib import contextmanager

import click

from aogm_cli.core.executors import SCHEDULER_ENV
from aogm_cli.core.occupancy_map import MODES
from aogm_cli.mapping.params import MapParams

quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress bar and no summary on stderr.")
SEED_LIMIT = 2**64  # seeds are stored as unsigned 64-bit integers (a log's seed attribute)


def seed_option_below(limit: int):
    """``--seed`` from 0 to ``limit`` - 1 (scikit-learn's random_state takes seeds below 2**32)."""
    return click.option("--seed", type=click.IntRange(min=0, max=limit - 1), default=0, show_default=True,
                        help="Random seed; the same seed gives identical outputs.")


seed_option = seed_option_below(SEED_LIMIT)


class FiniteFloat(click.FloatRange):
    """A float range that also refuses nan and +-inf (which compare false with every bound)."""

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"expected a finite number, got {value!r}", param, ctx)
        return v


FINITE = FiniteFloat()
POSITIVE = FiniteFloat(min=0, min_open=True)
NON_NEGATIVE = FiniteFloat(min=0)
ANGLE_DEG = FiniteFloat(min=0, max=180, min_open=True, max_open=True)  # a beam width (deg)


def degrees_shown(radians: float) -> float:
    """A default angle of the options (radians) as the command line shows and takes it."""
    return round(math.degrees(radians), 9)


# the sensor a log records, as the importers take it: option -> (flag, type, the default that a
# config dataclass (``io.importers``' TextOptions ...) gives, as the command line takes it)
SENSOR_OPTIONS = {
    "kind": ("--kind", click.Choice(["sonar", "laser"]), lambda d: d.kind),
    "max_range": ("--max-range", POSITIVE, lambda d: d.max_range),
    "min_range": ("--min-range", NON_NEGATIVE, lambda d: d.min_range),
    "beam_width": ("--beam-width", ANGLE_DEG, lambda d: degrees_shown(d.beam_width)),
    "noise_sigma": ("--noise-sigma", NON_NEGATIVE, lambda d: d.noise_sigma),
}


def sensor_options(defaults=None, **helps: str | None):
    """The ``SENSOR_OPTIONS`` named, each with its help text, listed in the order given (e.g.
    ``max_range="Max range (m)."``); with ``defaults`` (a config dataclass) each shows its default
    from there, else it has none (the importer decides)."""
    def decorate(f):
        for name, text in reversed(helps.items()):
            flag, kind, default = SENSOR_OPTIONS[name]
            shown = {} if defaults is None else {"default": default(defaults), "show_default": True}
            f = click.option(flag, type=kind, help=text, **shown)(f)
        return f
    return decorate


MIN_RESOLUTION = 1e-4  # m: a cell no finer than a world's finest truth_resolution
mode_choice = click.Choice(MODES)
mode_option = click.option("--mode", type=mode_choice, required=True, help="Which mapper.")
modes_option = click.option(
    "--modes", "modes_text",
    help=f"Comma-separated modes to compare.  [default: {','.join(MODES)}; with map files only, their modes]",
)
params_option = click.option(
    "--params", "params_file", type=click.Path(dir_okay=False),
    help="YAML with sections inverse_model:, em:, adaptive:, calibration:, surface:, exact: and key resolution:, "
         "used by every map made (every setting: docs/settings.md).",
)
forward_model_option = click.option(
    "--forward-model", "forward_model", type=click.Path(dir_okay=False),
    help="A sensor model file written by `aogm calibrate -o`: em and adaptive map with its sigma, p_rand, p_hit, "
         "p_max instead of calibrating (the building's part, the lobe and p_max, is still learned from each log). "
         "Refused when learned for another sensor.",
)
resolution_option = click.option(
    "--resolution", type=FiniteFloat(min=MIN_RESOLUTION),
    help=f"Cell size (m) for logs without truth.  [default: {MapParams().resolution}]"
)

calibrate_option = click.option(
    "--calibrate/--no-calibrate", "calibrate", default=None,
    help="em and adaptive: learn the forward model's sigma, p_rand, p_hit, p_max and lobe_deg from the log being"
         " mapped (which of them: calibration.learn in --params).  [default: on]",
)


def refuse_huge_grids(log_files, params, params_file: str | None, resolution_given: bool, max_memory: float) -> None:
    """``refuse_huge_grid`` for each of ``log_files`` (paths), opened in turn."""
    from aogm_cli.io.logfile import LogReader

    for path in log_files:
        with LogReader(path) as reader:
            refuse_huge_grid(reader, params, params_file, resolution_given, max_memory)


def refuse_huge_grid(reader, params, params_file: str | None, resolution_given: bool, max_memory: float) -> None:
    """Refuse (InputError) the open log ``reader`` when it has no truth and its grid alone, at the
    run's resolution, would take more than ``max_memory``, naming what set the resolution:
    ``--resolution``, else the params file's ``resolution``, else the log (poses or max range in the
    wrong unit?). Before the budget's estimate, which would otherwise overflow on an absurd grid."""
    from aogm_cli.core.budget import format_bytes
    from aogm_cli.core.errors import InputError
    from aogm_cli.mapping.map_cost import BYTES_PER_CELL
    from aogm_cli.report.log_check import grid_need

    res, path = params.resolution, reader.path
    if reader.has_truth:  # mapped on its truth grid: no resolution makes it larger
        return
    grid = grid_need(reader, res)
    need = grid.get("cells", 0.0) * BYTES_PER_CELL
    if not need > max_memory:
        return
    what = (f"would be {grid['height']:.3g} x {grid['width']:.3g} cells at {res:g} m, about "
            f"{format_bytes(need)} of memory (limit {format_bytes(max_memory)}) for the grid alone")
    if resolution_given:
        raise InputError(f"{res:g} m is too fine for {path}: its grid (the poses plus the sensor's reach) {what}; "
                         "expected a coarser resolution", key="--resolution")
    if params_file and res != MapParams().resolution:
        raise InputError(f"{res:g} m is too fine for {path}: its grid {what}; expected a coarser resolution",
                         file=params_file, key="resolution")
    raise InputError(f"the grid covering the poses plus the sensor's reach (max range {reader.sensor.max_range:g} "
                     f"m) {what}: poses or max range in the wrong unit? (or a coarser --resolution)", file=path)


def jobs_option(help_text: str):
    return click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True, help=help_text)


scheduler_option = click.option(
    "--scheduler", metavar="ADDRESS", envvar=SCHEDULER_ENV, show_envvar=True,
    help="Run every task on the Dask cluster whose scheduler is at ADDRESS (tcp://host:8786) instead of"
         " --jobs local processes; needs pip install aogm[dask] (see docs/cluster.md).",
)


def resume_option(help_text: str):
    return click.option("--resume", is_flag=True, help=help_text)


def report_failures(failures, what, other_failure: bool = False) -> None:
    """One line on stderr per failed task (``core.executors.Failure``; ``what(key)`` names it)
    and the count; then exit 2 when every failure was bad input, else 1 (``failure_status``;
    1 also when ``other_failure``, e.g. a failed gate)."""
    if not failures:
        return
    from aogm_cli.core.executors import failure_status

    for f in failures:
        click.echo(f"aogm: failed: {what(f.key)}: {f.message}", err=True)
    click.echo(f"aogm: {len(failures)} task(s) failed; the others finished", err=True)
    click.get_current_context().exit(1 if other_failure else failure_status(failures))


def expand_log_paths(args, key: str) -> list[str]:
    """Log arguments as files: a folder stands for its ``*.h5`` files, a glob (``logs/*_s?.h5``,
    quoted so that the shell leaves it) for its matches, each sorted by name; anything else is a
    file as given. InputError (naming ``key``) for a folder or glob that holds no file."""
    import glob
    from pathlib import Path

    from aogm_cli.core.errors import InputError

    paths: list[str] = []
    for arg in args:
        if Path(arg).is_dir():
            found = sorted(str(p) for p in Path(arg).glob("*.h5") if p.is_file())
            if not found:
                raise InputError("a folder without .h5 files; expected logs (LOG.h5) in it", file=arg, key=key)
        elif glob.has_magic(arg) and not Path(arg).exists():
            found = sorted(p for p in glob.glob(arg) if Path(p).is_file())
            if not found:
                raise InputError("no file matches this pattern; expected logs (LOG.h5)", file=arg, key=key)
        else:
            found = [arg]
        paths += found
    return list(dict.fromkeys(paths))


class SizeParam(click.ParamType):
    """A size in bytes: 16G, 500MB, 2e9 (``core.budget.parse_size``)."""

    name = "size"

    def convert(self, value, param, ctx):
        from aogm_cli.core.budget import parse_size

        try:
            return value if isinstance(value, float) else parse_size(value)
        except ValueError as exc:
            self.fail(str(exc), param, ctx)


def budget_options(f):
    """``--max-memory SIZE`` and ``--max-work N``: the limits a run's estimate is checked against
    before any work (``core.budget``); ``limits_of`` turns them into ``core.budget.Limits``."""
    f = click.option("--max-work", type=click.FloatRange(min=0, min_open=True),
                     help="Refuse runs estimated to take more elementary operations (ray casts, cell updates)."
                          "  [default: about an hour's worth]")(f)
    return click.option("--max-memory", type=SizeParam(), default="16G", show_default=True,
                        help="Refuse runs estimated to need more memory, e.g. 20G.")(f)


def threads_option(f):
    """``--threads N``: the threads EM's sweeps and set-up, and adaptive's evidence pass, may use
    (``core.budget.Limits.threads``)."""
    return click.option("--threads", type=click.IntRange(min=1), metavar="N",
                        help="Threads for EM's sweeps (em and adaptive): bands of the grid no reading joins are "
                             "swept at once; EM's set-up and adaptive's evidence pass run in parts of the "
                             "readings; the map is the same for any N.  [default: every core; with --jobs, "
                             "the cores shared among the workers]")(f)


def limits_of(max_memory: float, max_work: float | None, threads: int | None = None):
    from aogm_cli.core.budget import Limits

    return Limits(max_memory=max_memory, max_work=max_work, threads=threads)


class LazyDefault(click.Option):
    """An option whose ``default`` is a function called when first needed (a run that leaves the
    option out, or --help, which shows the value): defaults of modules too slow to load at start."""

    def get_default(self, ctx, call=True):
        return super().get_default(ctx, call=True)


def output_option(help_text: str, prefix: bool = False):
    """``-o/--output`` (required): a file, or with ``prefix`` a path that the command extends."""
    kind = click.Path() if prefix else click.Path(dir_okay=False)
    return click.option("-o", "--output", "output", required=True, type=kind, metavar="PREFIX" if prefix else None,
                        help=help_text)


def png_option(help_text: str):
    return click.option("--png", type=click.Path(dir_okay=False), help=help_text)


class DetectorParam(click.ParamType):
    """A detector file, or the name of a baseline of ``io.detectorfile.BASELINE_DETECTORS`` (read
    only when needed: that module loads every mapper)."""

    name = "detector"

    def get_metavar(self, param, ctx=None):
        from aogm_cli.io.detectorfile import BASELINE_DETECTORS

        return "|".join(("DETECTOR.h5", *BASELINE_DETECTORS))

    def convert(self, value, param, ctx):
        from aogm_cli.io.detectorfile import BASELINE_DETECTORS

        if value in BASELINE_DETECTORS:
            return value
        return click.Path(dir_okay=False).convert(value, param, ctx)


detector_option = click.option(
    "--detector", type=DetectorParam(),
    help="Detector file for adaptive mode, or a baseline that flags every reading or none.  [default: the packaged one]",
)


def detector_file(detector: str | None, modes) -> str | None:
    """The file that ``--detector`` makes an input of a run over ``modes`` (None for a baseline;
    the packaged detector when adaptive runs without one)."""
    if "adaptive" not in modes:
        return None
    from aogm_cli.io.detectorfile import BASELINE_DETECTORS, default_detector_path

    if detector is None:
        return str(default_detector_path())
    return None if detector in BASELINE_DETECTORS else detector


@contextmanager
def progress_bar(total: int | None, desc: str, quiet: bool, unit: str = "it"):
    """A tqdm bar on a terminal; nothing when quiet or when stderr is not a terminal.

    Yields a callback ``advance(n, total=None)`` that moves the bar by n (and sets its total when
    it was not known at the start: a bag's message count once it is open).
    """
    if quiet or not sys.stderr.isatty():
        yield lambda n, total=None: None
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=desc, unit=unit, leave=False, file=sys.stderr) as bar:
        def advance(n: int, total: int | None = None) -> None:
            if total is not None and bar.total != total:
                bar.total = total
            bar.update(n)

        yield advance


def check_executor(jobs: int, scheduler: str | None, batch: bool = True) -> None:
    """One executor per run: ``--jobs N`` (N > 1) and a ``--scheduler`` given on the command line
    are refused together (exit 2), and so is ``--scheduler`` where there is no batch of tasks to
    send (``batch`` false); a scheduler that comes from ``SCHEDULER_ENV`` alone is then ignored."""
    from click.core import ParameterSource

    from aogm_cli.core.errors import InputError

    ctx = click.get_current_context()
    explicit = scheduler is not None and ctx.get_parameter_source("scheduler") == ParameterSource.COMMANDLINE
    if explicit and not batch:
        raise InputError("runs a batch of tasks; give several worlds, --seeds or -o DIR/ (one log is simulated here)",
                         key="--scheduler")
    if scheduler is not None and batch and jobs > 1:
        raise InputError(f"--jobs {jobs} and a Dask scheduler ({scheduler}): choose one executor", key="--jobs")


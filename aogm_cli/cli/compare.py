"""``aogm compare``: logs (or their map files) x modes -> a metrics table, JSON, CSV, a figure,
and quality gates (``--require``, ``--require-checks``) that set the exit status; or the same
table and gates from the JSON of earlier runs (``--from-json``), merged, without mapping."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import click

from aogm_cli.cli.options import (
    budget_options,
    calibrate_option,
    check_executor,
    detector_file,
    detector_option,
    forward_model_option,
    jobs_option,
    limits_of,
    mode_choice,
    modes_option,
    params_option,
    progress_bar,
    quiet_option,
    refuse_huge_grids,
    report_failures,
    resume_option,
    scheduler_option,
    seed_option,
    threads_option,
)
from aogm_cli.io.outputs import resolve_outputs


@click.command("compare")
@click.argument("inputs", nargs=-1, required=True, metavar="LOG.h5|MAP.h5 ... | RESULTS.json ...",
                type=click.Path(dir_okay=False))
@modes_option
@detector_option
@params_option
@forward_model_option
@click.option("--json", "json_out", type=click.Path(dir_okay=False),
              help="Write the results as JSON (CONTRACT.md shape), to read back with --from-json.")
@click.option("--csv", "csv_out", type=click.Path(dir_okay=False),
              help="Write the table as CSV: one row per log and mode, every metric and check (see CSV above).")
@click.option("--figure", "figure_out", type=click.Path(dir_okay=False),
              help="Write a PNG: one row per log; truth and each mode's map, titled with accuracy and runtime.")
@click.option("--maps-dir", type=click.Path(file_okay=False),
              help="Also write every map computed here as DIR/<logstem>_<mode>.h5, to pass back in later.")
@click.option("--from-json", "from_json", is_flag=True,
              help="The arguments are --json files of earlier runs: merge their results, print the table and "
                   "apply the gates without mapping (see Merging above).")
@click.option("--require", "requires", multiple=True, metavar="EXPR",
              help="Gate, evaluated per log, e.g. 'adaptive.accuracy >= em.accuracy - 0.005', or once over the "
                   "logs when it aggregates, e.g. 'ci_low(adaptive.accuracy - em.accuracy) > -0.002'. Repeatable.")
@click.option("--require-checks", multiple=True, type=mode_choice,
              help="Gate: every world check of every log passes in this mode. Repeatable.")
@click.option("--summary-only", is_flag=True,
              help="Print the summary over the logs (and the baseline's findings) without the per-log tables.")
@click.option("--baseline", type=click.Path(dir_okay=False), metavar="OLD.json",
              help="Compare every log, mode and metric with an earlier run's --json file; exit 1 on a regression "
                   "beyond its tolerance (see Baseline above).")
@click.option("--tolerance", metavar="METRIC=X,...",
              help="With --baseline: how far each metric may get worse, e.g. accuracy=0.005,leak=0.01,runtime=1.25 "
                   "(runtime: a factor on its ratio to the standard map); the others keep their defaults.")
@click.option("--markdown", "markdown_out", type=click.Path(dir_okay=False), metavar="OUT.md",
              help="Write the summary and the baseline's findings as Markdown tables.")
@jobs_option("Map in this many worker processes (see Timings above).")
@scheduler_option
@resume_option("With --maps-dir: take the maps already there that are complete and valid for their log, mode and "
               "parameters (see Resuming above) instead of mapping again.")
@click.option("--holdout", type=float, metavar="FRACTION",
              help="Hold out every round(1/FRACTION)-th scan (0 < FRACTION <= 0.5), map the rest and score "
                   "each map on the held-out readings (see Held-out scores above).")
@click.option("--robot-radius", type=float, metavar="M",
              help="The disk robot whose planner leak, block, surface_recall, walls_kept, leak_vs_standard and "
                   "far_leak measure (see What a planner sees above; world checks keep their own radius).  "
                   "[default: 0.2]")
@calibrate_option
@seed_option
@quiet_option
@budget_options
@threads_option
def compare(inputs, modes_text, detector, params_file, forward_model, json_out, csv_out, figure_out, maps_dir, from_json, requires,
            require_checks, jobs, scheduler, resume, holdout, robot_radius, calibrate, seed, quiet, max_memory=16e9,
            max_work=None, threads=None, summary_only=False, baseline=None, tolerance=None, markdown_out=None):
    """Map every log in every mode, evaluate each map against the log's truth, and print a table
    (accuracy, occupied F1, Brier, ECE, checks passed, leak, block, surface recall, runtime, runtime
    relative to the standard map of the same log; every metric is defined in docs/comparing.md). em and adaptive learn their forward model from each log (--calibrate,
    the default; `aogm calibrate --help`), or take a robot's from --forward-model MODEL.

    A log without truth (an imported real log) is scored by re-casting its in-range readings
    against each map instead: the share whose endpoint (a sonar's occupied arc) lies on a cell
    believed occupied, the same within one cell, and the share of believed-free cells that a
    reading ends on (columns "Ends on occ.", "±1 cell", "Free contra."; JSON "consistency").

    Arguments may also be map files made earlier (aogm map, or --maps-dir): each is used for
    its mode instead of mapping again; its source_log attribute names the log with the truth.

    \b
    What a planner sees (a disk robot of --robot-radius, starting within 0.3 m of the
    trajectory, driving on observed cells below 0.5 with room for it):
      leak             cells it reaches that the robot cannot reach in truth, over the
                       truth-reachable observed cells (a wall the map lost)
      block            share of the truth-reachable observed cells it cannot reach
      surface_recall   truth wall-surface cells with a map cell above 0.5 within 0.1 m
    Without truth, against the standard map of the same log and grid (made for the purpose
    when it is not at hand; its own values are 1, 0 and 0):
      walls_kept       share of its cells at p >= 0.9 with a cell above 0.5 within 0.15 m
      leak_vs_standard cells reached beyond those reached in it, over the latter
      far_leak         cells reached farther than --robot-radius from every cell reached
                       in it, over the latter (a wall drawn thinner lets the robot a little
                       closer to it: that band is not counted)

    \b
    Held-out scores (--holdout FRACTION, with or without truth):
      every round(1/FRACTION)-th scan is held out, from an offset that --seed fixes; each map
      is made from the other scans and scored on the held-out readings: holdout_auc, the ROC
      AUC of its occupancy at each echo's cell on the sensor's axis against the cells that axis
      crosses up to two cells short of it (Hilbert maps' protocol); holdout_auc_band, the same
      with a reading's largest occupancy within 0.1 m of its range and its whole cone (the one
      to read for sonar; docs/comparing.md, Metrics); holdout_loglik, their mean log-likelihood under one
      fixed reference forward model (sigma 0.1 m, p_rand 0.1, p_hit 0.5, p_max 0.1; higher is
      better); holdout_readings and holdout_scans. The truth metrics (accuracy, ...) of a simulated
      log are then those of the map made from the kept scans. Map files given must have been
      made with the same --holdout and --seed (--maps-dir records them).

    \b
    Gates (exit status 1 when one fails, after --json, --csv and --figure are written):
      --require EXPR       MODE.METRIC names, numbers, + - * /, ( ), one of < <= > >= == !=
                           METRIC: accuracy, occupied_precision, occupied_recall,
                           occupied_f1, brier, ece, runtime (= runtime_s), checks_passed (fraction),
                           leak, block, surface_recall, walls_kept, leak_vs_standard,
                           far_leak;
                           with --holdout: holdout_auc, holdout_auc_band, holdout_loglik,
                           holdout_readings, holdout_scans
      --require-checks M   every check of every log passes in mode M
      aggregates           mean, sd, ci_low, ci_high, min, max, median of an expression
                           per log, evaluated once over the logs of the run, e.g.
                           "mean(adaptive.accuracy - em.accuracy) >= 0",
                           "min(em.checks_passed) == 1", "median(adaptive.runtime_ratio) <= 60"
                           (runtime_ratio: runtime over the same log's standard map); every
                           name of such a gate inside an aggregate, every log must have it

    \b
    Summary, printed after the per-log tables (--summary-only: alone), in --json ("summary"),
    --csv (rows with a "statistic" column) and --markdown: per world (its logs at several
    seeds) and over all logs, for each mode and metric the count, mean, standard deviation and
    the 95% confidence interval of the mean (Student t: mean +- t(0.975, n-1) sd/sqrt(n));
    for each pair of modes the paired difference on the logs both have (the later mode minus
    the earlier: em - standard, adaptive - standard, adaptive - em), its interval, and on how
    many logs the first is better, equal or worse (wins/ties/losses); runtime as the ratio to
    the same log's standard map.

    \b
    Baseline (--baseline OLD.json [--tolerance METRIC=X,...]): every log, mode and metric in
    both this run and OLD.json (an earlier --json) is compared; logs are matched by file name
    and content (a log whose data changed is named as changed and not compared); a metric
    worse by more than its tolerance is a regression, better by more an improvement; each
    world's means over its matched logs are compared alike. Default tolerances: accuracy
    0.005, brier 0.005, ece 0.01, occupied_precision/recall/f1 0.02, checks_passed 0 (no check
    may be lost), leak 0.01, block 0.01, surface_recall 0.02, walls_kept 0.01,
    leak_vs_standard 0.01, far_leak 0.005, holdout_auc(_band) 0.005, holdout_loglik 0.01,
    runtime 1.25 (a factor on the ratio to the same run's standard map, so a slower machine
    is not a regression). Exit 1 on a regression, after the outputs are written.

    \b
    CSV (--csv): one row per log and mode, always these columns in this order, empty where a
    value does not apply: log, world, mode, truth, runtime_s, runtime_vs_standard, accuracy,
    occupied_precision, occupied_recall, occupied_f1, brier, ece, checks_passed, leak, block,
    surface_recall (truth), walls_kept, leak_vs_standard, far_leak (no truth), consistency_* (logs
    without truth), holdout_* (--holdout), learned_sigma, learned_p_rand, learned_p_hit,
    learned_p_max, learned_from_readings (the forward model an em or adaptive map's
    calibration learned); then one check:NAME column (true/false) per world check, and
    statistic (empty on these rows). The summary's rows follow: log empty, world the world or
    "all logs", mode the mode or MODE-OTHER (a paired difference), statistic one of n, mean, sd,
    ci_low, ci_high, median, min, max (and wins, ties, losses of a difference), the metric
    columns holding that number.

    \b
    Merging (--from-json): the arguments are --json files of earlier runs; their results are
    merged (one log and mode in two files: exit 2 naming both; every file must hold the same
    --holdout split, or none), printed and gated as if compared here, and written again with
    --json and --csv. Nothing is mapped: --figure, --maps-dir, --robot-radius and the mapping
    options are refused (exit 2).

    \b
    Timings: each map's runtime_s is measured inside the process that builds it, around the
    mapping work only (the mapper excludes file I/O and one-time compilation). With --jobs N > 1
    the workers compete for cores and memory bandwidth, so for fair runtimes use --jobs 1 (the
    default) or N no larger than the number of cores. Runtimes relative to standard are always
    taken within one log. --scheduler ADDRESS (or AOGM_SCHEDULER) runs each map as one task on
    a Dask cluster, timed the same way inside its worker; logs and maps are passed as paths,
    so every worker must see them at the same paths.

    \b
    Failed tasks: a map that fails (bad input found while mapping, a lost worker) is reported
    on stderr per log and mode, the others finish and are tabled, written and gated; the exit
    status is then 2 when every failure was bad input, else 1 (1 too when a gate fails).
    Inputs checked before any work (an unreadable log, a bad option) still stop the run first.

    \b
    Resuming (--resume, with --maps-dir): a map DIR/<logstem>_<mode>.h5 already there is taken
    as given, not made again, when it reads back whole and valid, is of that mode, its
    provenance records the log's current sha256, and it was made with the same parameters,
    --holdout split and (adaptive) detector; any other is mapped again and replaced.

    \b
    Examples:
      aogm compare door.h5 hall.h5 --modes standard,em --json results.json --figure cmp.png
      aogm compare door.h5 --maps-dir maps/ --require "em.accuracy >= standard.accuracy"
      aogm compare door.h5 --robot-radius 0.25 --require "em.leak <= 0.02"
      aogm compare maps/door_standard.h5 maps/door_em.h5 --require-checks em
      aogm compare door.h5 --holdout 0.1 --require "em.holdout_loglik >= standard.holdout_loglik"
      aogm compare --from-json door.json hall.json --csv all.csv --require-checks em
      aogm compare logs/*.h5 --summary-only --require "ci_low(adaptive.accuracy - em.accuracy) > -0.002"
      aogm compare logs/*.h5 --json new.json --baseline old.json --markdown report.md
    """
    from aogm_cli.report.gates import parse_gate

    gates = [parse_gate(text) for text in requires]  # malformed -> exit 2 before any work
    against = _Against.read(baseline, tolerance, markdown_out, summary_only)
    if from_json:
        _refuse_mapping_options(click.get_current_context())
        _compare_results_files(list(inputs), gates, require_checks, json_out, csv_out, quiet, against)
        return

    from aogm_cli.evaluation.holdout import HoldoutSplit
    from aogm_cli.io.provenance import provenance
    from aogm_cli.map_files import resolve_params
    from aogm_cli.report import compare as lib
    from aogm_cli.report.scoring import CompareJob
    from aogm_cli.report.table import log_labels, print_table

    split = None if holdout is None else HoldoutSplit(holdout, seed).validate()
    radius = _robot_radius(robot_radius)
    check_executor(jobs, scheduler)
    params = resolve_params(params_file, {"calibration": {"enabled": calibrate}})
    job = CompareJob(params, detector, split, limits_of(max_memory, max_work, _threads(threads, jobs)), radius,
                     forward_model)
    entries = lib.collect_inputs(list(inputs))
    modes = lib.parse_modes(modes_text) if modes_text else lib.default_modes(entries)
    _check_gates(gates, require_checks, modes, split is not None)
    resumed = _resume(entries, modes, maps_dir, job, resume, quiet)
    outputs = [("--json", json_out), ("--csv", csv_out), ("--figure", figure_out), ("--markdown", markdown_out)]
    read = _check_outputs(inputs, entries, modes, (params_file, detector_file(detector, modes), forward_model, baseline),
                          outputs, maps_dir)
    record = provenance(read)  # the inputs as read, the time the run starts
    _check_budget(entries, modes, job, params_file)
    _warn_learned_over(entries, modes, job, params_file)
    n_tasks = sum(mode not in e.maps for e in entries for mode in modes)
    with progress_bar(n_tasks, "compare", quiet, unit="map") as advance:
        results, failures = lib.run_comparison(entries, modes, job, jobs, scheduler, maps_dir, keep_maps=bool(figure_out),
                                               on_map=lambda i, mode, r: advance(1))
    for path, differs in lib.given_maps_differences(results, params, resumed):
        click.echo(f"aogm: note: {path} was made with other {', '.join(differs)} parameters than "
                   "this comparison's; it is reported as it is", err=True)
    labels = log_labels(entries)
    analysis, gated = against.analyse(results, gates, require_checks, labels)  # bad aggregates: exit 2, no output
    if not summary_only:
        print_table(results, labels, quiet)
    against.show(analysis, quiet)
    files = lib.output_files(results, record, json_out, csv_out, analysis=analysis)
    if figure_out:
        from aogm_cli.report.figure import comparison_figure_png

        files.append((Path(figure_out), comparison_figure_png(entries, results, labels, radius)))
    _commit_outputs(files, maps_dir, [json_out, csv_out, figure_out, markdown_out], quiet)
    failed = _report_gates(gated, analysis, exit_now=not failures)
    report_failures(failures, lambda key: f"{key[0]} ({key[1]})", failed)


def _threads(threads: int | None, jobs: int) -> int | None:
    """EM's threads in each of ``jobs`` workers: --threads, or the cores shared among them."""
    if threads is not None or jobs <= 1:
        return threads
    from aogm_cli.core.budget import Limits

    return max(1, Limits().thread_count() // jobs)


def _robot_radius(value: float | None) -> float:
    """--robot-radius, checked: a positive number of metres (default ``evaluation.planner.ROBOT_RADIUS``)."""
    import math

    from aogm_cli.evaluation.planner import ROBOT_RADIUS

    if value is None:
        return ROBOT_RADIUS
    if not (math.isfinite(value) and value > 0):
        from aogm_cli.core.errors import InputError

        raise InputError(f"expected a positive number of metres, got {value:g}", key="--robot-radius")
    return value


def _resume(entries, modes, maps_dir, job, resume: bool, quiet: bool) -> set[str]:
    """--resume: the --maps-dir maps taken as they are (``report.compare.resume_maps``)."""
    if not resume:
        return set()
    if not maps_dir:
        from aogm_cli.core.errors import InputError

        raise InputError("needs --maps-dir (the maps of an earlier run to take up again)", key="--resume")
    from aogm_cli.report.compare import resume_maps

    taken = resume_maps(entries, modes, maps_dir, job)
    if not quiet:
        click.echo(f"resume: {len(taken)} map(s) in {maps_dir} already complete, not mapped again", err=True)
    return set(taken)


def _check_outputs(inputs, entries, modes, files, outputs, maps_dir) -> list[str]:
    """Every output (``outputs``: (option, path) of --json, --csv, --figure; the --maps-dir maps to
    write) against every input: the arguments, the logs that map files name, and ``files``
    (--params, the detector file). Returns those inputs (each once, for the provenance)."""
    from aogm_cli.report.compare import maps_dir_targets

    targets = maps_dir_targets(entries, modes, maps_dir) if maps_dir else {}
    every = [str(p) for p in (*inputs, *(e.path for e in entries), *files) if p is not None]
    resolve_outputs(every, [*outputs, *(("--maps-dir", t) for t in targets.values())], [("--maps-dir", maps_dir)])
    return list(dict.fromkeys(every))


def _check_budget(entries, modes, job, params_file: str | None) -> None:
    """Refuse (exit 2) before any work a map to make whose grid or estimate exceeds ``job.limits``."""
    from aogm_cli.map_files import check_logs

    to_map = [(e.path, mode) for e in entries for mode in modes if mode not in e.maps]
    refuse_huge_grids(list(dict.fromkeys(path for path, _ in to_map)), job.params, params_file, False,
                      job.limits.max_memory)
    check_logs(to_map, job.params, job.limits)
    if job.forward_model:  # a model of another sensor than a log's is refused before any map is made
        from aogm_cli.io.logfile import LogReader
        from aogm_cli.map_files import given_model

        for path in dict.fromkeys(path for path, mode in to_map if mode != "standard"):
            with LogReader(path) as reader:
                given_model(job.forward_model, reader.sensor, path)


# options that only mapping uses: refused with --from-json (parameter name -> option)
MAPPING_OPTIONS = {"figure_out": "--figure", "maps_dir": "--maps-dir", "modes_text": "--modes", "detector": "--detector",
                   "params_file": "--params", "forward_model": "--forward-model", "jobs": "--jobs", "scheduler": "--scheduler", "resume": "--resume", "holdout": "--holdout", "robot_radius": "--robot-radius", "calibrate": "--calibrate/--no-calibrate",
                   "seed": "--seed", "max_memory": "--max-memory", "max_work": "--max-work",
                   "threads": "--threads"}


def _warn_learned_over(entries, modes, job, params_file: str | None) -> None:
    """``map_files.learned_over``'s warnings for the first em or adaptive map to make of each log, each printed once."""
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.map_files import learned_over, set_em_keys

    keys = set_em_keys(params_file)
    warnings: dict[str, None] = {}
    for e in entries:
        mode = next((m for m in modes if m != "standard" and m not in e.maps), None)
        if keys and mode is not None:
            with LogReader(e.path) as reader:
                warnings |= dict.fromkeys(learned_over(mode, job.params, keys, reader, job.forward_model, job.detector))
    for warning in warnings:
        click.echo(warning, err=True)


def _refuse_mapping_options(ctx: click.Context) -> None:
    """InputError (exit 2) naming the first option given that needs maps or mapping."""
    from click.core import ParameterSource

    from aogm_cli.core.errors import InputError

    for name, option in MAPPING_OPTIONS.items():
        source = ctx.get_parameter_source(name)
        if source is not None and source not in (ParameterSource.DEFAULT, ParameterSource.ENVIRONMENT):
            need = "the maps" if name in ("figure_out", "maps_dir", "robot_radius") else "mapping"
            raise InputError(f"needs {need}; --from-json reads results only (drop {option}, or compare the logs "
                             "or map files instead)", key=option)


def _check_gates(gates, require_checks, modes, holdout: bool) -> None:
    """Gates name modes among those compared, and held-out scores only with ``holdout``."""
    from aogm_cli.report.gates import check_gate_metrics, check_gate_modes

    check_gate_metrics(gates, holdout)
    check_gate_modes(gates, modes)
    for mode in require_checks:
        if mode not in modes:
            from aogm_cli.core.errors import InputError

            raise InputError(f"mode {mode!r} is not among the modes compared ({', '.join(modes)})", key="--require-checks")


def _compare_results_files(paths, gates, require_checks, json_out, csv_out, quiet, against: _Against) -> None:
    """--from-json: merge the results of the --json files ``paths``, print, write and gate them."""
    from aogm_cli.io.provenance import provenance
    from aogm_cli.io.results import merge_results_files
    from aogm_cli.report.compare import output_files
    from aogm_cli.report.table import print_table, result_labels

    record = provenance(paths)  # the files as read, the time the run starts
    merged = merge_results_files(paths)
    _check_gates(gates, require_checks, merged.modes, merged.holdout is not None)
    resolve_outputs([*paths, *([against.baseline] if against.baseline else [])],
                    [("--json", json_out), ("--csv", csv_out), ("--markdown", against.markdown_out)])
    labels = result_labels(merged.results)
    analysis, gated = against.analyse(merged.results, gates, require_checks, labels)
    if not against.summary_only:
        print_table(merged.results, labels, quiet)
    against.show(analysis, quiet)
    files = output_files(merged.results, record, json_out, csv_out, merged.holdout, analysis)
    _commit_outputs(files, None, [json_out, csv_out, against.markdown_out], quiet)
    _report_gates(gated, analysis)


@dataclass(frozen=True)
class _Against:
    """What a comparison is held against besides its gates: the --baseline file's results (read before any work,
    so a bad one exits 2 first) and its tolerances; and where its conclusions go (--markdown, --summary-only)."""

    baseline: str | None
    old: list | None
    tolerances: dict
    markdown_out: str | None
    summary_only: bool

    @classmethod
    def read(cls, baseline: str | None, tolerance: str | None, markdown_out: str | None, summary_only: bool) -> _Against:
        from aogm_cli.core.errors import InputError
        from aogm_cli.io.results import read_results_file
        from aogm_cli.report.baseline import parse_tolerances

        if tolerance is not None and baseline is None:
            raise InputError("is given without --baseline; expected --baseline OLD.json beside it", key="--tolerance")
        tolerances = parse_tolerances(tolerance)
        old = read_results_file(baseline)[0] if baseline else None
        return cls(baseline, old, tolerances, markdown_out, summary_only)

    def analyse(self, results, gates, require_checks, labels):
        """(the ``report.compare.Analysis`` of ``results``, the gates evaluated: (count, failures)); InputError
        (exit 2) from an aggregate that cannot be computed, before anything is written."""
        from aogm_cli.report.baseline import compare_to_baseline
        from aogm_cli.report.compare import Analysis
        from aogm_cli.report.gates import evaluate_comparison_gates
        from aogm_cli.report.summary import summarize

        found = None if self.old is None else compare_to_baseline(results, self.old, self.baseline, self.tolerances)
        gated = evaluate_comparison_gates(gates, require_checks, results, labels)
        return Analysis(summarize(results), found, self.markdown_out), gated

    def show(self, analysis, quiet: bool) -> None:
        from aogm_cli.report.summary_table import print_baseline, print_summary

        print_summary(analysis.summary, quiet)
        if analysis.baseline is not None:
            print_baseline(analysis.baseline)


def _commit_outputs(files: list[tuple[Path, bytes]], maps_dir: str | None, written: list[str | None],
                    quiet: bool) -> None:
    """The output ``files`` (``report.compare.output_files``, the figure) in one commit: all
    written, or none (and a folder --maps-dir made here removed again); then "wrote" each of
    ``written`` given (unless quiet)."""
    from aogm_cli.io.atomic import write_files_atomically

    made = [f for f in (Path(maps_dir), *Path(maps_dir).parents) if not f.exists()] if maps_dir else []
    if files and made:
        Path(maps_dir).mkdir(parents=True)
    try:
        write_files_atomically(files)
    except BaseException:
        for folder in made:
            if folder.exists() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    if not quiet:
        for path in written:
            if path:
                click.echo(f"wrote {path}", err=True)


def _report_gates(gated, analysis, exit_now: bool = True) -> bool:
    """Print each failed gate of ``gated`` ((count, failures) of --require and --require-checks) and the count, and
    the baseline's regressions' count; exit 1 when a gate failed or a value regressed (``exit_now``), else leave the
    exit to the failed tasks' report."""
    total, failures = gated
    for failure in failures:
        click.echo(str(failure))
    if total:
        click.echo(f"gates: {total - len(failures)} of {total} passed")
    if failures:
        click.echo(f"aogm: {len(failures)} of {total} gates failed", err=True)
    regressions = 0 if analysis.baseline is None else len(analysis.baseline.regressions)
    if regressions:
        click.echo(f"aogm: {regressions} regressions against the baseline {analysis.baseline.baseline}", err=True)
    if (failures or regressions) and exit_now:
        click.get_current_context().exit(1)
    return bool(failures or regressions)

"""``aogm calibrate``: learn EM's forward model from a log and print it (no map written), or
write the sensor's model as a file (``-o MODEL``) that maps other logs of the same robot
(``--forward-model MODEL``)."""

from __future__ import annotations

import dataclasses

import click

from aogm_cli.cli.map_log import parameter_options, parameter_overrides
from aogm_cli.cli.options import (
    budget_options,
    detector_file,
    detector_option,
    limits_of,
    params_option,
    progress_bar,
    quiet_option,
    refuse_huge_grids,
    resolution_option,
    threads_option,
)
from aogm_cli.io.outputs import resolve_outputs


@click.command()
@click.argument("log_file", metavar="LOG.h5", type=click.Path(dir_okay=False))
@click.option("--mode", type=click.Choice(["em", "adaptive"]), default="em", show_default=True,
              help="Whose maps the model is fitted at.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Also write the sensor's learned model (sigma, p_rand, p_hit, p_max, the "
                   "sensor it fits) as a model file for `aogm map/compare --forward-model`.")
@detector_option
@params_option
@resolution_option
@parameter_options
@quiet_option
@budget_options
@threads_option
def calibrate(log_file, mode, output, detector, params_file, resolution, quiet, max_memory=16e9, max_work=None,
              threads=None, **options) -> None:
    """Learn the forward model (sigma, p_rand, p_hit, p_max, the lobe) from LOG.h5 and print it.

    Thrun's EM learns its sensor model too: at a binary map, the expectations of each
    reading's cause (random, max-range dropout, the k-th obstacle of its cone, no obstacle
    detected) give the parameters in closed form (p_rand the mean random expectation, p_max
    the mean dropout expectation, p_hit the expected detections over the expected obstacles
    examined, sigma^2 the expected squared range error of the detections), iterated at that
    map until they settle. Round 0 maps with the configured model made at least 0.1 m
    broad; each round fits at the last map and maps again, until no parameter moves by more
    than 2%, or after 4 rounds. Every value is clipped to bounds (docs/algorithms.md,
    "Calibration's constants"). calibration.learn lists what is learned (any of sigma, p_rand,
    p_hit, p_max, lobe_deg; all five by default): a value it lists is learned even when --params
    sets it (a warning says so; the value only starts the fit). The lobe (lobe_deg, lobe_range) is learned from the echoes at the thinned walls
    before the rounds. Beams whose core meets a surface (a cell heard from one direction) more
    obliquely than em.specular_deg (15; 90: never) before their echo are taken as deflected there.
    `aogm map` and `aogm compare` do all this by default in em and adaptive modes.

    \b
    Example:
      aogm calibrate door.h5
      aogm calibrate robot.h5 -o robot_model.yaml && aogm map other.h5 --mode em --forward-model robot_model.yaml -o m.h5
    """
    inputs = (log_file, params_file, detector_file(detector, (mode,)))
    resolve_outputs(inputs, [("-o", output)] if output else [])
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.io.modelfile import model_bytes
    from aogm_cli.io.provenance import provenance
    from aogm_cli.map_files import learned_over, map_file, model_record, resolve_params, set_em_keys
    from aogm_cli.mapping.calibration import TUNING
    from aogm_cli.report.calibration_table import calibration_table, lobe_line

    made = provenance(inputs) if output else None  # the inputs as read, the time the run starts
    overrides = parameter_overrides(resolution, True, options)
    params = resolve_params(params_file, overrides)
    params = dataclasses.replace(params, calibration=dataclasses.replace(params.calibration, carried=False))
    refuse_huge_grids([log_file], params, params_file, resolution is not None, max_memory)
    with LogReader(log_file) as reader:
        for warning in learned_over(mode, params, set_em_keys(params_file, overrides), reader, None, detector):
            click.echo(warning, err=True)
    with progress_bar(params.em.max_sweeps * (TUNING.rounds + 1), f"calibrate ({mode})", quiet,
                      unit="sweep") as advance:
        result = map_file(log_file, mode, params, detector, lambda phase, done, total: advance(1),
                          limits=limits_of(max_memory, max_work, threads))
    record = result.stats.get("calibration")
    if record is None:  # adaptive without clusters: EM never ran
        raise click.UsageError(f"{log_file}: the detector flagged no cluster; nothing to calibrate in adaptive mode")
    click.echo(calibration_table(record))
    if (result.learned or {}).get("lobe") is not None:
        click.echo(lobe_line(result.learned["lobe"]))
    if output:
        from aogm_cli.io.atomic import write_files_atomically

        with LogReader(log_file) as reader:
            sensor = reader.sensor
        write_files_atomically([(output, model_bytes(model_record(result.learned), sensor, str(log_file), made))])
        if not quiet:
            click.echo(f"{output}: the sensor's model, for --forward-model", err=True)

"""``aogm map``: log -> map file (standard, em or adaptive), optionally with a PNG."""

from __future__ import annotations

import click

from aogm_cli.cli.options import (
    budget_options,
    calibrate_option,
    detector_file,
    detector_option,
    forward_model_option,
    limits_of,
    mode_option,
    output_option,
    params_option,
    png_option,
    progress_bar,
    quiet_option,
    refuse_huge_grid,
    resolution_option,
    threads_option,
)
from aogm_cli.io.outputs import resolve_outputs
from aogm_cli.mapping.params import EMConfig
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.inverse_model import InverseModelConfig

# (option, section, key, type, help); defaults are read from the config dataclasses
PARAMETER_OPTIONS = (
    ("--model", "inverse_model", "model", click.Choice(["elfes", "constant", "exact"]), "Inverse model (exact: derived from the forward model)."),
    ("--l-occ", "inverse_model", "l_occ", float, "Log-odds of the occupied arc."),
    ("--l-free", "inverse_model", "l_free", float, "Log-odds of the free region."),
    ("--clamp-min", "inverse_model", "clamp_min", float, "Lower log-odds clamp."),
    ("--clamp-max", "inverse_model", "clamp_max", float, "Upper log-odds clamp."),
    ("--alpha", "inverse_model", "alpha", float, "Obstacle thickness (m) of the occupied arc."),
    ("--sigma", "em", "sigma", float, "EM: range noise of the forward model (m)."),
    ("--p-rand", "em", "p_rand", float, "EM: prior of a random reading."),
    ("--p-hit", "em", "p_hit", float, "EM: detection probability of each obstacle."),
    ("--p-max", "em", "p_max", float, "EM: point mass of max-range dropouts."),
    ("--prior", "em", "prior_occupied", float, "EM: prior occupancy of a cell."),
    ("--max-sweeps", "em", "max_sweeps", click.IntRange(min=1), "EM: sweep limit."),
)


def _default(section: str, key: str):
    if section == "inverse_model":
        return getattr(InverseModelConfig(), key)
    em = EMConfig()
    return getattr(em.forward if hasattr(ForwardModelConfig, key) else em, key)


def parameter_options(f):
    """Decorate ``f`` with one option per mapping parameter (None when not given)."""
    for opt, section, key, kind, text in reversed(PARAMETER_OPTIONS):
        f = click.option(opt, f"{section}__{key}", type=kind, help=f"{text}  [default: {_default(section, key)}]")(f)
    return f


def parameter_overrides(resolution: float | None, calibrate: bool | None, options: dict) -> dict:
    """``resolve_params``' overrides from the CLI: --resolution, --calibrate/--no-calibrate and
    the ``parameter_options`` (None where an option was not given)."""
    overrides: dict = {"resolution": resolution, "inverse_model": {}, "em": {}, "calibration": {"enabled": calibrate}}
    for name, value in options.items():
        section, key = name.split("__")
        overrides[section][key] = value
    return overrides


@click.command("map")
@click.argument("log_file", metavar="LOG.h5", type=click.Path(dir_okay=False))
@mode_option
@output_option("Map file to write (HDF5).")
@png_option("Also render the map into this PNG.")
@detector_option
@params_option
@forward_model_option
@resolution_option
@parameter_options
@calibrate_option
@quiet_option
@budget_options
@threads_option
def map_log(log_file, mode, output, png, detector, params_file, forward_model, resolution, calibrate, quiet,
            max_memory=16e9, max_work=None, threads=None, **options) -> None:
    """Build an occupancy-grid map from LOG.h5.

    \b
    standard  log-odds with the Elfes sonar inverse model, each cell on its own
    em        Thrun's EM with forward sensor models over every observed cell
    adaptive  standard everywhere; EM only inside the clusters the detector flags

    Adaptive mode: the detector (--detector, or the one packaged with aogm; see
    `aogm train --help` for its inputs and labels) flags readings from neighbouring
    sonar ranges; each flagged reading's band (its cone from 0.2 m before its range to alpha
    beyond it) marks the cells there that the standard map holds occupied and not at its free
    clamp; with the contested and weak cells (section adaptive: of --params) they form
    clusters (8-connected). EM runs over each group of clusters that share a reading, with every
    other cell held at the map outside them thresholded at p = 0.5; cluster cells get EM's
    residual probability. Outside the clusters the map is the standard map thinned by the exact
    inverse model where the sensor's model is known before mapping (the packaged detector's
    ring, --forward-model), its free cells that no reading holds free unobserved, else the
    standard map; its probabilities on EM's scale (adaptive.outside; docs/algorithms.md).

    em and adaptive learn their forward model from the log itself (--calibrate, the default;
    `aogm calibrate --help`), or take a robot's from --forward-model MODEL: the map's params hold
    the values configured, its `learned` attribute what was learned and where the model came
    from, /stats the calibration's rounds.

    Maps of a simulated log use its truth grid; other logs get the poses' bounds plus the
    sensor's max range at --resolution. Every parameter used is written into the map file.

    \b
    Example:
      aogm map door.h5 --mode standard -o door_map.h5 --png door_map.png
    """
    inputs = (log_file, params_file, detector_file(detector, (mode,)), forward_model)
    resolve_outputs(inputs, [("-o", output), ("--png", png)])  # before loading the mappers
    import hashlib

    from aogm_cli.io.atomic import write_files_atomically
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.io.mapfile import map_bytes
    from aogm_cli.io.provenance import provenance
    from aogm_cli.map_files import calibration_notice, learned_over, map_file, resolve_params, set_em_keys
    from aogm_cli.report.calibration_table import learned_line

    overrides = parameter_overrides(resolution, calibrate, options)
    params = resolve_params(params_file, overrides)
    digest = hashlib.sha256()
    with LogReader(log_file, digest) as reader:  # one read of the log checks its seal and hashes it
        record = provenance(inputs, hashed={log_file: digest.hexdigest()})  # the inputs as read, the run's start
        refuse_huge_grid(reader, params, params_file, resolution is not None, max_memory)
        for warning in learned_over(mode, params, set_em_keys(params_file, overrides), reader, forward_model, detector):
            click.echo(warning, err=True)
        with progress_bar(params.em.max_sweeps, f"map ({mode})", quiet, unit="sweep") as advance:
            def progress(phase, done, total):
                advance(1)

            result = map_file(log_file, mode, params, detector, progress, limits=limits_of(max_memory, max_work, threads),
                              model=forward_model, source=reader)
    outputs = [(output, map_bytes(result, record))]
    if png:
        from aogm_cli.report.picture import map_png

        outputs.append((png, map_png(result.grid, result.probability, result.observed, result.clusters,
                                     title=f"{mode} map of {log_file} ({result.runtime_s:.2f} s)")))
    write_files_atomically(outputs)  # the map and the PNG, all or nothing
    notice = calibration_notice(log_file, result)
    if notice:
        click.echo(notice, err=True)
    learned = learned_line(log_file, result)
    if learned and not quiet:
        click.echo(learned, err=True)
    if not quiet:
        click.echo(f"{output}: {mode} map {result.grid.height}x{result.grid.width} in {result.runtime_s:.3f} s", err=True)

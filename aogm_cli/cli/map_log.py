"""``aogm map``: log -> map file (standard, em or adaptive), optionally with a PNG."""

from __future__ import annotations

import click

from aogm_cli.cli.options import output_option, progress_bar, quiet_option


@click.command("map")
@click.argument("log_file", metavar="LOG.h5", type=click.Path(dir_okay=False))
@click.option("--mode", type=click.Choice(["standard", "em", "adaptive"]), required=True, help="Which mapper.")
@output_option("Map file to write (HDF5).")
@click.option("--png", type=click.Path(dir_okay=False), help="Also render the map into this PNG.")
@click.option("--detector", type=click.Path(dir_okay=False), help="Detector file for --mode adaptive (default: the packaged one).")
@click.option("--params", "params_file", type=click.Path(dir_okay=False), help="YAML with sections inverse_model:, em: and key resolution:.")
@click.option("--resolution", type=float, help="Cell size (m) for logs without truth.  [default: 0.05]")
@click.option("--model", type=click.Choice(["elfes", "constant"]), help="Inverse model.  [default: elfes]")
@click.option("--l-occ", type=float, help="Log-odds of the occupied arc.  [default: 0.85]")
@click.option("--l-free", type=float, help="Log-odds of the free region.  [default: -0.41]")
@click.option("--clamp-min", type=float, help="Lower log-odds clamp.  [default: -2.0]")
@click.option("--clamp-max", type=float, help="Upper log-odds clamp.  [default: 3.5]")
@click.option("--alpha", type=float, help="Obstacle thickness (m) of the occupied arc.  [default: 0.1]")
@click.option("--sigma", type=float, help="EM: range noise of the forward model (m).  [default: 0.03]")
@click.option("--p-rand", type=float, help="EM: prior of a random reading.  [default: 0.05]")
@click.option("--p-hit", type=float, help="EM: detection probability of each obstacle.  [default: 0.7]")
@click.option("--p-max", type=float, help="EM: point mass of max-range dropouts.  [default: 0.1]")
@click.option("--prior", "prior_occupied", type=float, help="EM: prior occupancy of a cell.  [default: 0.3]")
@click.option("--max-sweeps", type=click.IntRange(min=1), help="EM: sweep limit.  [default: 20]")
@click.option("--em-start", type=click.Choice(["standard", "empty"]), help="EM: start map.  [default: standard]")
@quiet_option
def map_log(log_file, mode, output, png, detector, params_file, resolution, quiet, **options) -> None:
    """Build an occupancy-grid map from LOG.h5.

    \b
    standard  log-odds with the Elfes sonar inverse model, each cell on its own
    em        Thrun's EM with forward sensor models over every observed cell
    adaptive  standard everywhere; EM only inside the clusters the detector flags

    Maps of a simulated log use its truth grid; other logs get the poses' bounds plus the
    sensor's max range at --resolution. Every parameter used is written into the map file.

    \b
    Example:
      aogm map door.h5 --mode standard -o door_map.h5 --png door_map.png
    """
    from aogm_cli.mapfile import write_map_file
    from aogm_cli.mapping import mapper
    from aogm_cli.mapping.params import resolve_params

    inverse_keys = ("model", "l_occ", "l_free", "clamp_min", "clamp_max", "alpha")
    overrides = {
        "resolution": resolution,
        "inverse_model": {k: options[k] for k in inverse_keys},
        "em": {k: v for k, v in options.items() if k not in inverse_keys and k != "em_start"} | {"start": options["em_start"]},
    }
    params = resolve_params(params_file, overrides)
    with progress_bar(params.em.max_sweeps, f"map ({mode})", quiet, unit="sweep") as advance:
        def progress(phase, done, total):
            advance(1)

        if mode == "standard":
            result = mapper.map_standard(log_file, params, progress)
        elif mode == "em":
            result = mapper.map_em(log_file, params, progress)
        else:
            result = mapper.map_adaptive(log_file, params, detector, progress)
    write_map_file(output, result, inputs=(log_file,))
    if png:
        from aogm_cli.render import render_map

        render_map(png, result.grid, result.probability, result.observed, result.clusters,
                   title=f"{mode} map of {log_file} ({result.runtime_s:.2f} s)")
    if not quiet:
        click.echo(f"{output}: {mode} map {result.grid.height}x{result.grid.width} in {result.runtime_s:.3f} s", err=True)

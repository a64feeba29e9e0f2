"""``aogm export``: map file -> ROS map_server files (trinary PGM, scale PNG, YAML)."""

from __future__ import annotations

import click

from aogm_cli.cli.options import output_option, quiet_option
from aogm_cli.io.map_server import MAP_SAVER_FREE_THRESH, MAP_SAVER_OCCUPIED_THRESH
from aogm_cli.io.outputs import resolve_outputs


@click.command()
@click.argument("map_file", metavar="MAP.h5", type=click.Path(dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["ros"]), default="ros", show_default=True, help="Export format.")
@output_option("Output prefix: writes PREFIX.pgm, PREFIX.yaml, PREFIX.png, PREFIX_scale.yaml.", prefix=True)
@click.option("--occupied-thresh", type=click.FloatRange(0, 1), default=MAP_SAVER_OCCUPIED_THRESH, show_default=True,
              help="p above this is occupied (0) in the PGM.")
@click.option("--free-thresh", type=click.FloatRange(0, 1), default=MAP_SAVER_FREE_THRESH, show_default=True,
              help="p below this is free (254) in the PGM.")
@quiet_option
def export(map_file: str, fmt: str, output: str, occupied_thresh: float, free_thresh: float, quiet: bool) -> None:
    """Export MAP.h5 for ROS map_server, as map_saver writes maps.

    PREFIX.pgm is trinary (0 occupied, 254 free, 205 unknown) with PREFIX.yaml beside it;
    PREFIX.png keeps the probabilities (grey = 255 * (1 - p), unobserved transparent) and
    PREFIX_scale.yaml loads it in map_server's scale mode.

    \b
    Example:
      aogm export door_map.h5 --format ros -o door_map
      rosrun map_server map_server door_map.yaml
    """
    from aogm_cli.core.errors import InputError
    from aogm_cli.io.map_saver import export_paths, write_map
    from aogm_cli.io.mapfile import read_map_file

    if free_thresh > occupied_thresh:
        raise InputError(f"expected free-thresh <= occupied-thresh ({occupied_thresh:g}), got {free_thresh:g}", key="--free-thresh")
    resolve_outputs([map_file], [("-o", path) for path in export_paths(output)])
    m = read_map_file(map_file)
    paths = write_map(output, m.probability, m.observed, m.grid.resolution, (m.grid.origin_x, m.grid.origin_y, 0.0),
                      occupied_thresh=occupied_thresh, free_thresh=free_thresh)
    if not quiet:
        click.echo(" ".join(str(p) for p in paths), err=True)

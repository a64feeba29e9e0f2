"""``aogm render``: map file -> PNG (grey probabilities, unknown tinted, clusters outlined)."""

from __future__ import annotations

import click

from aogm_cli.cli.options import output_option, quiet_option
from aogm_cli.io.outputs import resolve_outputs


@click.command()
@click.argument("map_file", metavar="MAP.h5", type=click.Path(dir_okay=False))
@output_option("PNG to write.")
@click.option("--title", help="Title above the map (default: mode, source log and runtime).")
@quiet_option
def render(map_file: str, output: str, title: str | None, quiet: bool) -> None:
    """Draw MAP.h5 as a PNG: white free, black occupied, grey between; unobserved cells pale
    blue; clusters (adaptive maps) outlined in orange; axes in metres.

    \b
    Example:
      aogm render door_map.h5 -o door_map.png
    """
    resolve_outputs([map_file], [("-o", output)])
    from aogm_cli.io.atomic import write_files_atomically
    from aogm_cli.io.mapfile import read_map_file
    from aogm_cli.report.picture import map_png

    m = read_map_file(map_file)
    write_files_atomically([(output, map_png(m.grid, m.probability, m.observed, m.clusters,
                                             title=title or f"{m.mode} map of {m.source_log} ({m.runtime_s:.2f} s)"))])
    if not quiet:
        click.echo(f"{output}: {m.mode} map {m.grid.height}x{m.grid.width}", err=True)

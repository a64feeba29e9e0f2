"""``aogm check``: what a log holds before it is mapped (``report.log_check``): a table, or JSON;
exit 0 with warnings, 3 with ``--strict`` when there is any."""

from __future__ import annotations

import json

import click

from aogm_cli.cli.options import MIN_RESOLUTION, FiniteFloat, SizeParam
from aogm_cli.report.log_check import CheckLimits

STRICT_STATUS = 3  # --strict and some warning

_positive = FiniteFloat(min=0, min_open=True)


def limit_options(f):
    """The warnings' thresholds as options (defaults from ``CheckLimits``)."""
    d = CheckLimits()
    for name, kind, default, text in reversed((
        ("--max-speed", _positive, d.max_speed, "A pose moving faster between two scans (m/s) is a jump."),
        ("--max-turn", _positive, d.max_turn, "A heading turning faster between two scans (rad/s) is a jump."),
        ("--gap-factor", FiniteFloat(min=1), d.gap_factor, "A time step this many median periods long is a gap."),
        ("--resolution", FiniteFloat(min=MIN_RESOLUTION), d.resolution,
         "Cell size (m) of the grid a map of a log without truth would need."),
        ("--max-memory", SizeParam(), "16G", "Warn when a standard map would need more memory, e.g. 20G."),
    )):
        f = click.option(name, type=kind, default=default, show_default=True, help=text)(f)
    return f


@click.command()
@click.argument("log_file", metavar="LOG.h5", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the findings as JSON instead of a table.")
@click.option("--strict", is_flag=True, help=f"Exit {STRICT_STATUS} when there is any warning.")
@click.option("--all-sensors", is_flag=True, help="List every sensor in the table (of more than 32, only those with a "
              "finding are listed).")
@limit_options
def check(log_file: str, as_json: bool, strict: bool, all_sensors: bool, max_speed: float, max_turn: float,
          gap_factor: float, resolution: float, max_memory: float) -> None:
    """Check what LOG.h5 holds before mapping it, and warn about what looks wrong.

    \b
    per sensor  the share of no-echo and invalid readings; a sensor that never gave a valid echo
                (disabled?) or whose readings never change while the robot moves (stuck);
                readings closer than the min range (warned over 1% of its valid readings) or
                inside the robot: no farther than the sensor is from the robot's centre (warned
                over half of them)
    scans       pose jumps faster than --max-speed or turns faster than --max-turn between two
                scans; time gaps over --gap-factor median periods; time running backwards;
                poses or times that are not finite
    grid        the cells a map would need (the truth grid, else the poses plus the sensor's
                reach at --resolution) and the memory of a standard map of them

    The same summary ends every `aogm import`. Exit status 0 (also with warnings), 2 for a file
    that is not a valid log, 3 with --strict when there is any warning.

    \b
    Example:
      aogm check p3dx.h5
      aogm check p3dx.h5 --json --strict --max-speed 1.5
    """
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.report.log_check import check_log

    limits = CheckLimits(max_speed=max_speed, max_turn=max_turn, gap_factor=gap_factor, resolution=resolution,
                         max_memory=max_memory)
    with LogReader(log_file) as reader:
        result = check_log(reader, limits)
    if as_json:
        click.echo(json.dumps(result.as_dict(), indent=2))
    else:
        click.echo("\n".join(result.lines(all_sensors)))
    if strict and result.warnings:
        click.get_current_context().exit(STRICT_STATUS)

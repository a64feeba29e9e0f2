"""``aogm simulate``: world YAML -> simulated sonar log (HDF5) with its truth."""

from __future__ import annotations

import click

from aogm_cli.cli.options import (
    budget_options,
    limits_of,
    output_option,
    png_option,
    progress_bar,
    quiet_option,
    seed_option,
)
from aogm_cli.io.outputs import resolve_outputs


def world_inputs(world_file: str, world) -> list[str]:
    """The files a world is read from: its YAML, and a floor plan's map_server YAML and image."""
    files = [world_file]
    if world.floorplan is not None:
        from aogm_cli.io.map_server import read_map_yaml

        files += [world.floorplan.map, read_map_yaml(world.floorplan.map).image]
    return files


@click.command()
@click.argument("world_file", metavar="WORLD.yaml", type=click.Path(dir_okay=False))
@output_option("Log file to write (HDF5).")
@seed_option
@png_option("Also draw the truth and the trajectory into this PNG.")
@quiet_option
@budget_options
def simulate(world_file: str, output: str, seed: int, png: str | None, quiet: bool,
             max_memory: float = 16e9, max_work: float | None = None) -> None:
    """Simulate a sonar ring driving through WORLD.yaml and write the log with its truth.

    The log holds /scans (time, pose, ranges), /sensors and /truth (occupancy grid, each
    reading's cause and noise-free range). The same seed gives identical arrays.

    \b
    Example:
      aogm simulate worlds/corridor_door.yaml -o door.h5 --seed 1 --png door_truth.png
    """
    from aogm_cli.core import budget
    from aogm_cli.world.budget import simulation_estimate
    from aogm_cli.world.loader import load_world

    world = load_world(world_file)
    limits = limits_of(max_memory, max_work)
    budget.check(simulation_estimate(world), limits, file=world_file)  # before any work
    inputs = world_inputs(world_file, world)
    resolve_outputs(inputs, [("-o", output), ("--png", png)])
    from aogm_cli.io.atomic import write_files_atomically
    from aogm_cli.io.logfile import log_bytes
    from aogm_cli.io.provenance import provenance
    from aogm_cli.simulation.sonar import simulate as run_simulation
    from aogm_cli.world.trajectory import trajectory_poses

    record = provenance(inputs)  # the inputs as read, the time the run starts
    n_scans = len(trajectory_poses(world)[0])
    with budget.using(limits), progress_bar(n_scans, "simulate", quiet, unit="scan") as advance:
        log = run_simulation(world, seed=seed, progress=advance)
    outputs = [(output, log_bytes(log, record))]
    if png:
        from aogm_cli.report.picture import truth_png

        outputs.append((png, truth_png(log, title=world.name)))
    write_files_atomically(outputs)  # the log and the PNG, all or nothing
    if not quiet:
        click.echo(f"{output}: {log.n_scans} scans x {log.sensor.count} sonars from {world_file} (seed {seed})", err=True)

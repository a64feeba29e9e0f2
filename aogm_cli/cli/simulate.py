"""``aogm simulate``: world YAML -> simulated sonar log (HDF5) with its truth."""

from __future__ import annotations

from pathlib import Path

import click

from aogm_cli.cli.options import (
    SEED_LIMIT,
    budget_options,
    check_executor,
    jobs_option,
    limits_of,
    png_option,
    progress_bar,
    quiet_option,
    report_failures,
    resume_option,
    scheduler_option,
    seed_option,
)
from aogm_cli.io.outputs import resolve_outputs


def world_inputs(world_file: str, world) -> list[str]:
    """The files a world is read from: its YAML, and a floor plan's map_server YAML and image."""
    files = [world_file]
    if world.floorplan is not None:
        files += [world.floorplan.map, world.floorplan.plan.image]
    return files


@click.command()
@click.argument("world_files", metavar="WORLD.yaml [WORLD.yaml ...]", nargs=-1, required=True,
                type=click.Path(dir_okay=False))
@click.option("-o", "--output", "output", required=True, type=click.Path(),
              help="Log file to write (HDF5); with several worlds or --seeds, a folder (DIR/).")
@seed_option
@click.option("--seeds", "seeds_text", metavar="LIST",
              help="Simulate every world at each of these seeds, e.g. 1-100 or 1,5,9-12: the logs go to "
                   "-o DIR/ as DIR/<world>_s<seed>.h5 (see Many worlds and seeds above).")
@png_option("Also draw the truth and the trajectory into this PNG (one world and seed only).")
@jobs_option("With several worlds or seeds: simulate in this many worker processes.")
@scheduler_option
@resume_option("With -o DIR/: skip the logs already there that read back as valid logs of the same world text "
               "and seed.")
@quiet_option
@budget_options
def simulate(world_files: tuple[str, ...], output: str, seed: int, seeds_text: str | None, png: str | None,
             jobs: int, scheduler: str | None, resume: bool, quiet: bool,
             max_memory: float = 16e9, max_work: float | None = None) -> None:
    """Simulate a sonar ring driving through WORLD.yaml and write the log with its truth.

    The log holds /scans (time, pose, ranges), /sensors and /truth (occupancy grid, each
    reading's cause and noise-free range). The same seed gives identical arrays.

    \b
    Many worlds and seeds (several WORLD.yaml, or --seeds, or -o ending in /):
      every world at every seed (--seeds, else --seed) is one task, written atomically to
      DIR/<world file stem>_s<seed>.h5; --jobs N runs them in N local processes, --scheduler
      on a Dask cluster (paths must be the same on every worker). Every world is read and
      checked before any work. A task that fails is reported and the others finish; the exit
      status is then 2 when every failure was bad input, else 1. --resume skips a log that is
      already there and reads back as a valid log of the same world text and seed (a
      truncated or damaged one is simulated again). The arrays are those of one-by-one runs.

    \b
    Examples:
      aogm simulate worlds/corridor_door.yaml -o door.h5 --seed 1 --png door_truth.png
      aogm simulate worlds/corridor_door.yaml worlds/office_doors.yaml --seeds 1-100 -o logs/ --jobs 2
    """
    from aogm_cli.core.errors import InputError

    batch = len(world_files) > 1 or seeds_text is not None or output.endswith(("/", "\\"))
    check_executor(jobs, scheduler, batch)
    if not batch:
        if resume:
            raise InputError("needs several worlds or seeds written to -o DIR/", key="--resume")
        ctx = click.get_current_context()
        click.Path(dir_okay=False).convert(output, next(p for p in ctx.command.params if p.name == "output"), ctx)
        _simulate_one(world_files[0], output, seed, png, quiet, limits_of(max_memory, max_work))
        return
    if png:
        raise InputError("draws one world's truth; not with several worlds, --seeds or -o DIR/ (drop --png, or "
                         "simulate that world alone)", key="--png")
    ctx = click.get_current_context()
    from click.core import ParameterSource

    if seeds_text is not None and ctx.get_parameter_source("seed") != ParameterSource.DEFAULT:
        raise InputError("give --seed or --seeds, not both", key="--seeds")
    seeds = parse_seeds(seeds_text) if seeds_text is not None else [seed]
    _simulate_many(list(world_files), seeds, output, jobs, scheduler, resume, quiet, limits_of(max_memory, max_work))


def parse_seeds(text: str) -> list[int]:
    """``"1-3,7"`` -> [1, 2, 3, 7]; InputError (key --seeds) on anything else or a repeated seed."""
    from aogm_cli.core.errors import InputError

    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        if not lo.isdigit() or (hi and not hi.isdigit()) or (hi and int(hi) < int(lo)):
            raise InputError(f"expected seeds >= 0 as N, N-M (M >= N) or a comma list of them, e.g. 1-100, got {text!r}",
                             key="--seeds")
        if int(hi or lo) >= SEED_LIMIT:
            raise InputError(f"expected seeds below 2**64 ({SEED_LIMIT}), got {int(hi or lo)}", key="--seeds")
        seeds += range(int(lo), int(hi or lo) + 1)
    if len(set(seeds)) != len(seeds):
        raise InputError(f"a seed is repeated in {text!r}", key="--seeds")
    return seeds


def _load_checked(world_file: str, limits):
    """The world of ``world_file`` and the files it is read from, its estimate checked against
    ``limits`` (before any work)."""
    from aogm_cli.world.simulation_cost import load_checked_world

    world = load_checked_world(world_file, limits)
    return world, world_inputs(world_file, world)


def _simulate_one(world_file: str, output: str, seed: int, png: str | None, quiet: bool, limits) -> None:
    """One world at one seed to the log ``output`` (and its truth picture ``png``)."""
    from aogm_cli.core import budget

    world, inputs = _load_checked(world_file, limits)
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


def simulate_file(world_file: str, seed: int, output: str, limits, record: dict) -> int:
    """Simulate ``world_file`` at ``seed`` and write the log to ``output`` atomically, with the
    provenance ``record`` made before the run; the number of scans. A task of ``--seeds`` runs
    (top-level, so that worker processes and Dask workers can run it; paths in, a number out)."""
    from aogm_cli.core import budget
    from aogm_cli.io.atomic import write_files_atomically
    from aogm_cli.io.logfile import log_bytes
    from aogm_cli.simulation.sonar import simulate as run_simulation
    from aogm_cli.world.loader import load_world

    world = load_world(world_file)
    with budget.using(limits):
        log = run_simulation(world, seed=seed)
    _remove_temporaries_on_sigterm()
    write_files_atomically([(output, log_bytes(log, record))])
    return log.n_scans


def _remove_temporaries_on_sigterm() -> None:
    """In a --jobs worker process (its main thread, SIGTERM at the default): the SIGTERM that ends
    it (``core.interrupts.end_workers``) first removes the temporaries it is writing."""
    import os
    import signal
    import threading

    from aogm_cli.io.atomic import remove_temporaries

    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        return

    def end(signum, frame):
        remove_temporaries()
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, end)


def simulated_log_is_complete(path: Path, world_text: str, seed: int) -> bool:
    """Whether ``path`` reads back whole as a valid log with truth of ``world_text`` at ``seed``
    (--resume; a truncated or damaged file, another world or seed: no)."""
    from aogm_cli.core.errors import InputError
    from aogm_cli.io.logfile import read_log

    if not path.is_file():
        return False
    try:
        log = read_log(path)
    except (InputError, OSError):
        return False
    return log.seed == seed and log.truth is not None and log.truth.world == world_text


def _simulate_many(world_files: list[str], seeds: list[int], folder: str, jobs: int, scheduler: str | None,
                   resume: bool, quiet: bool, limits) -> None:
    """Every world at every seed to ``folder``/<world>_s<seed>.h5 (``core.executors.run_tasks``)."""
    from aogm_cli.core.errors import InputError
    from aogm_cli.core.executors import Task, run_tasks
    from aogm_cli.io.provenance import provenance

    worlds = {}
    for world_file in dict.fromkeys(world_files):
        stem = Path(world_file).stem
        if stem in worlds:
            raise InputError(f"two worlds would write {stem}_s<seed>.h5: {worlds[stem][0]} and {world_file}; rename one",
                             key="WORLD.yaml")
        worlds[stem] = (world_file, *_load_checked(world_file, limits))
    targets = {(stem, s): Path(folder) / f"{stem}_s{s}.h5" for stem in worlds for s in seeds}
    resolve_outputs([f for _, _, inputs in worlds.values() for f in inputs],
                    [("-o", str(t)) for t in targets.values()], [("-o", folder)])
    Path(folder).mkdir(parents=True, exist_ok=True)
    done = {key for key, t in targets.items() if resume and simulated_log_is_complete(t, worlds[key[0]][1].text, key[1])}
    records = {stem: provenance(inputs) for stem, (_, _, inputs) in worlds.items()}  # as read, at the start
    tasks = [Task(key, simulate_file, (worlds[key[0]][0], key[1], str(t), limits, records[key[0]]))
             for key, t in targets.items() if key not in done]
    with progress_bar(len(tasks), "simulate", quiet, unit="log") as advance:
        written, failures = run_tasks(tasks, jobs, scheduler, on_done=lambda key, n: advance(1))
    if not quiet:
        click.echo(f"simulate: {len(written)} log(s) written to {folder}, {len(done)} already complete (--resume), "
                   f"{len(failures)} failed", err=True)
    report_failures(failures, lambda key: f"{worlds[key[0]][0]} seed {key[1]}")

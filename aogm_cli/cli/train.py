"""``aogm train``: simulated logs -> the cluster detector (a small MLP) in a detector file."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import click

from aogm_cli.cli.options import (
    LazyDefault,
    expand_log_paths,
    output_option,
    progress_bar,
    quiet_option,
    seed_option_below,
)
from aogm_cli.detector.features import FeatureSpec
from aogm_cli.io.outputs import resolve_outputs
from aogm_cli.training.config import TrainingConfig


@click.command()
@click.argument("log_files", metavar="LOG.h5|DIR|'GLOB' ...", nargs=-1, required=True, type=click.Path())
@output_option("Detector file to write (HDF5).")
@seed_option_below(2**32)  # scikit-learn's random_state
@click.option("--validation-logs", "validation_logs", multiple=True, type=click.Path(),
              help="A log (a folder or a quoted glob of logs) held out for validation (repeat for more).  [default: the last max(1, n // 4) of n >= 2 logs]")
@click.option("--hidden", type=click.IntRange(min=1, max=256), default=TrainingConfig.hidden, show_default=True, help="Units of the hidden layer.")
@click.option("--activation", type=click.Choice(["tanh", "relu", "logistic"]), default=TrainingConfig.activation,
              show_default=True,
              help="Activation of the hidden layer.")
@click.option("--beta", type=click.FloatRange(min=0, min_open=True), default=TrainingConfig.beta, show_default=True,
              help="The flag threshold maximises F_beta on the training data; beta < 1 favours precision.")
@click.option("--ring-neighbours", type=click.IntRange(min=0), default=FeatureSpec.ring_neighbours, show_default=True,
              help="Sonars on each side of a reading in the same ring reading.")
@click.option("--time-neighbours", type=click.IntRange(min=0), default=FeatureSpec.time_neighbours, show_default=True,
              help="Scans before and after a reading, same sonar.")
@click.option("--arc-wrong-min", type=click.IntRange(min=0), cls=LazyDefault, default=lambda: _labels().arc_wrong_min,
              show_default=True,
              help="Label rule (c): wrong standard-map cells on a reading's occupied arc that make y = 1 (0 = rule off).")
@click.option("--sensor-models/--no-sensor-models", default=False, show_default=True,
              help="Also calibrate each training log (em) and carry the median model of each sensor in the detector, "
                   "for maps with calibration.carried.")
@quiet_option
def train(log_files, output, seed, validation_logs, hidden, activation, beta, ring_neighbours, time_neighbours,
          arc_wrong_min, sensor_models, quiet) -> None:
    """Train the cluster detector on simulated logs and write it to a detector file.

    \b
    Input (the paper's P = [p_1 .. p_R]): for reading (scan t, sonar j), the ranges of
    sonars j-2 .. j+2 of the same ring reading (wrapping around the ring) and of sonar j at
    scans t-1 and t+1 (clipped at the ends): R = 7 with the defaults, divided by max_range (+inf, NaN -> 1),
    plus each neighbour minus the reading and a missing-echo flag per measurement.
    \b
    Label y = 1 (from the log's truth) when the reading is erroneous -- its cause is random
    or specular/multipath, it has no echo although a surface is in the cone, or it is off
    the ideal range by more than 0.3 m -- or when its cone straddles a depth edge of the
    truth map within 2.5 m: two adjacent of 31 sub-rays whose first hits differ by more than
    1.2 x nearer + 0.3 m (door frames, gaps between objects, openings narrower than the
    cone's arc) -- or when the standard map of the same log (default parameters, computed
    during training) is wrong against the truth on at least --arc-wrong-min cells of the
    reading's occupied arc (its cone's cells within alpha/2 of the range; wrong: p > 0.5 on
    a free cell or p < 0.5 on an occupied one): the oblique cones that draw walls too thick
    towards the robot, close openings or miss surfaces, where EM should decide instead.
    \b
    Network: one hidden layer (--hidden units, --activation), logistic output, fitted by
    scikit-learn's MLPClassifier with random_state = --seed. Validation is by world: whole
    logs are held out. The flag threshold maximises F_beta on the training data; the default
    beta 0.25 weighs precision over recall (a false flag costs EM time in a needless cluster,
    a missed one is mostly covered by its flagged neighbours' bands; on the bundled worlds
    it gives a threshold near 0.9 and more accurate adaptive maps than beta = 1). Precision,
    recall, F1 and counts on training and validation logs are printed and stored in the file,
    and so are the logs themselves (attribute training_logs, JSON): per training and
    validation log its file name, world, whether that world is a realistic variant (it has
    an errors: section), its errors, seed, scan count and source.
    \b
    Logs: files, folders (their *.h5 files, sorted by name) or quoted globs ('logs/*_s?.h5',
    their matches sorted by name); a log named twice counts once.
    \b
    Examples:
      aogm train out/lab.h5 out/hall.h5 out/office.h5 --validation-logs out/office.h5 -o detector.h5 --seed 1
      aogm train logs/ --validation-logs 'logs/office_doors_s*.h5' -o detector.h5 --seed 1
    """
    log_files = expand_log_paths(log_files, "LOG.h5")
    validation_logs = expand_log_paths(validation_logs, "--validation-logs")
    resolve_outputs([*log_files, *validation_logs], [("-o", output)])  # before loading scikit-learn
    from aogm_cli.core.errors import InputError
    from aogm_cli.io.detectorfile import save_detector
    from aogm_cli.io.logfile import read_log
    from aogm_cli.io.provenance import provenance
    from aogm_cli.map_files import learn_sensor_models, resolve_params
    from aogm_cli.mapping.standard import truth_grid_map
    from aogm_cli.training.fit import split_by_world, train_detector
    from aogm_cli.training.labels import LabelDefinition

    spec = FeatureSpec(ring_neighbours, time_neighbours)
    config = TrainingConfig(hidden=hidden, activation=activation, seed=seed, beta=beta)
    train_paths, validation_paths = split_by_world(log_files, validation_logs)
    record = provenance([*train_paths, *validation_paths])  # the inputs as read, the time the run starts
    steps = (2 if sensor_models else 1) * len(train_paths) + len(validation_paths) + 1
    with progress_bar(steps, "train", quiet, unit="step") as advance:
        train_logs = [(p, read_log(p)) for p in train_paths]
        validation_logs_read = [(p, read_log(p)) for p in validation_paths]
        for p, log in train_logs + validation_logs_read:
            if log.n_scans == 0:
                raise InputError("no scans (/scans/time is empty); a detector learns from readings", file=p,
                                 key="/scans")
        detector = train_detector(train_logs, validation_logs_read, spec, LabelDefinition(arc_wrong_min=arc_wrong_min), config,
                                  advance, standard_map_of=truth_grid_map)
        if sensor_models:  # each training log's sensor calibrated (em), the median per sensor
            detector = dataclasses.replace(detector, sensor_models=learn_sensor_models(train_paths, resolve_params(),
                                                                                      advance))
    save_detector(output, detector, record)
    click.echo(format_metrics(detector.metrics))
    if not quiet:
        click.echo(f"{output}: detector {detector.training['network']}, threshold {detector.threshold:.2f}", err=True)


def _labels():
    """The label rule's defaults (its module loads scipy: read only when needed)."""
    from aogm_cli.training.labels import LabelDefinition

    return LabelDefinition()


def format_metrics(metrics: dict) -> str:
    """The metrics as a small table: one row for training, one for validation."""
    lines = [f"{'':12s}{'precision':>10s}{'recall':>8s}{'F1':>7s}{'readings':>10s}{'positive':>10s}{'flagged':>9s}  logs"]
    for part in ("train", "validation"):
        m = metrics.get(part)
        if not m:
            lines.append(f"{part:12s}  (no {part} logs)")
            continue
        logs = ", ".join(Path(p).name for p in m.get("logs", []))
        lines.append(
            f"{part:12s}{m['precision']:10.3f}{m['recall']:8.3f}{m['f1']:7.3f}{m['n_samples']:10d}"
            f"{m['n_positive']:10d}{m['n_flagged']:9d}  {logs}"
        )
    return "\n".join(lines)

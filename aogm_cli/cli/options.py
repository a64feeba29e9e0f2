"""Option decorators and helpers shared by the subcommands (quiet, seed, progress bars).

Used by: simulate (quiet, seed), map (quiet), train (quiet, seed), compare (quiet).
"""

from __future__ import annotations

import sys
from contextlib import contextmanager

import click

quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
seed_option = click.option(
    "--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed; the same seed gives identical outputs."
)


def output_option(help_text: str):
    return click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False), help=help_text)


@contextmanager
def progress_bar(total: int, desc: str, quiet: bool, unit: str = "it"):
    """A tqdm bar on a terminal; nothing when quiet or when stderr is not a terminal.

    Yields a callback ``advance(n)`` that moves the bar by n.
    """
    if quiet or not sys.stderr.isatty():
        yield lambda n: None
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=desc, unit=unit, leave=False, file=sys.stderr) as bar:
        yield bar.update

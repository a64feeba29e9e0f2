"""The ``aogm`` command group (one small module per subcommand) and its one error boundary: InputError
-> a line on stderr and exit 2; OutputError and anything else -> exit 1 (a traceback with ``--debug``);
SIGINT, SIGTERM, SIGHUP -> 128 + N (``core.interrupts``)."""

from __future__ import annotations

import sys
import traceback
import warnings

import click

from aogm_cli import __version__
from aogm_cli.core import interrupts
from aogm_cli.core.errors import InputError, OutputError


class AogmGroup(click.Group):
    """A click group that turns library errors into the exit codes of CONTRACT.md."""

    def main(self, *args, **kwargs):
        """The commands with SIGINT, SIGTERM and SIGHUP handled (``core.interrupts``: temporaries
        removed, workers ended, exit 128 + N); ``aogm_cli.__main__`` installs them even earlier."""
        previous = None if interrupts.installed() else interrupts.install()
        try:
            return super().main(*args, **kwargs)
        finally:
            if previous is not None:
                interrupts.restore(previous)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        """The subcommand ``name`` (``COMMANDS``), its module imported now."""
        if name not in COMMANDS:
            return None
        import importlib

        module, attr = COMMANDS[name]
        return getattr(importlib.import_module(f"aogm_cli.cli.{module}"), attr)

    def invoke(self, ctx: click.Context):
        with warnings.catch_warnings():
            if ctx.params.get("debug"):
                show_warnings()
            else:
                quiet_library_warnings()
            return self._invoke(ctx)

    def _invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except InputError as exc:
            if ctx.obj and ctx.obj.get("debug"):
                traceback.print_exc()
            click.echo(f"aogm: error: {exc}", err=True)
            ctx.exit(2)
        except OutputError as exc:  # a full disk, any OS error while writing: exit 1
            if ctx.obj and ctx.obj.get("debug"):
                traceback.print_exc()
            click.echo(f"aogm: error: {exc}", err=True)
            ctx.exit(1)
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except KeyboardInterrupt:  # only when the handlers are not installed (e.g. embedded)
            click.echo("aogm: interrupted (SIGINT)", err=True)
            ctx.exit(interrupts.exit_status(2))
        except Exception as exc:  # noqa: BLE001 - the contract: one line, exit 1
            if ctx.obj and ctx.obj.get("debug"):
                traceback.print_exc()
            else:
                click.echo(f"aogm: failed: {exc.__class__.__name__}: {exc} (run with --debug for a traceback)", err=True)
            ctx.exit(1)


def quiet_library_warnings() -> None:
    """Silence what numpy, h5py, matplotlib, numba and scikit-learn warn about (shown with --debug):
    a run's outcome is its exit status and its messages, not the libraries' asides."""
    warnings.simplefilter("ignore")
    # a library that adds its own "always" filter on import (numba's NumbaWarning) still goes here
    warnings.showwarning = lambda *args, **kwargs: None


def show_warnings() -> None:
    """With --debug: every warning, with its source line, on stderr."""
    warnings.simplefilter("default")

    def show(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    warnings.showwarning = show


@click.group(cls=AogmGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="aogm")
@click.option("--debug", is_flag=True, help="Show a traceback on errors.")
@click.pass_context
def main(ctx: click.Context, debug: bool) -> None:
    """Occupancy-grid maps from sonar readings: standard, EM and adaptive (clusters) mappers.

    \b
    aogm simulate worlds/corridor_door.yaml -o door.h5
    aogm map door.h5 --mode standard -o door_map.h5 --png door_map.png
    """
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug
    keep_cone_templates()


def keep_cone_templates() -> None:
    """Cone templates that take a while to build are kept on disk for the next run
    (``io.template_store``; the sensor models take the store, they write no file)."""
    from aogm_cli.io import template_store
    from aogm_cli.sensor_models import cone_build

    cone_build.use_store(template_store.STORE)


# each subcommand's module and object, imported when the command runs (or --help lists them):
# a command loads only what it uses (``aogm map`` neither rosbags nor Pillow's importers)
COMMANDS = {
    "simulate": ("simulate", "simulate"),
    "map": ("map_log", "map_log"),
    "calibrate": ("calibrate", "calibrate"),
    "train": ("train", "train"),
    "render": ("render", "render"),
    "export": ("export", "export"),
    "import": ("import_log", "import_log"),
    "compare": ("compare", "compare"),
    "info": ("info", "info"),
    "check": ("check", "check"),
}


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

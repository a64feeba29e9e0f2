"""Entry point of the console script ``aogm`` and of ``python -m aogm_cli``: the signal handlers
are installed first (stdlib only), the commands and their heavy imports (numba) after.
"""

import sys


def main():
    from aogm_cli.core import interrupts

    interrupts.install()
    from aogm_cli.cli import main as commands

    return commands()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

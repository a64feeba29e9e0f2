"""Entry point for ``python -m aogm_cli``."""

from aogm_cli.cli import main

main()

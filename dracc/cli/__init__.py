"""The command-line interface: a thin typer layer over :mod:`dracc.pipeline` and friends."""

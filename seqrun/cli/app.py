"""The one typer application; command modules register themselves on it."""

from __future__ import annotations

import typer
from typer.core import TyperGroup

from seqrun.cli.argv import expand_bus_kwargs


class _SeqrunGroup(TyperGroup):
    """Accepts python-can's ``--bus-kwargs K=V K=V`` (see :mod:`seqrun.cli.argv`)."""

    def parse_args(self, ctx, args):
        return super().parse_args(ctx, expand_bus_kwargs(args))


app = typer.Typer(
    cls=_SeqrunGroup,
    name="seqrun",
    help="Declarative sequence runner for PowerCube robot arms (Schunk LWA 3).",
    no_args_is_help=True,
    rich_markup_mode=None,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
    add_completion=False,
)

sim_app = typer.Typer(help="The simulated arm.", no_args_is_help=True)
pose_app = typer.Typer(help="Predefined poses.", no_args_is_help=True)
app.add_typer(sim_app, name="sim")
app.add_typer(pose_app, name="pose")


def _show_version(value: bool) -> None:
    if value:
        from seqrun import __version__

        typer.echo(f"seqrun {__version__}")
        raise typer.Exit(0)


@app.callback()
def _seqrun(version: bool = typer.Option(
        False, "--version", "-V", is_eager=True, callback=_show_version,
        help="Print seqrun's version and exit.")) -> None:
    """Declarative sequence runner for PowerCube robot arms (Schunk LWA 3)."""

"""Options and arguments shared by the commands."""
from __future__ import annotations

import click

from ..config import LANDMARK_FIELDS
from ..model import PRETRAINED
from ..pictures.render import UP_AXES

MODEL_ARG = dict(nargs=-1, required=True, type=click.Path(dir_okay=False), metavar="[CHECKPOINT|NAME] MESH")
UP_OPTION = click.option("--up", type=click.Choice(["auto", *UP_AXES]), default="auto", show_default=True,
                         callback=lambda ctx, param, value: None if value == "auto" else value,
                         help="The mesh's up axis in pictures (auto: +y or +z, by how the mesh stands).")
PREPARE_OPTION = click.option("--prepare", is_flag=True, help="Run the geodata pipeline first (watertight, remesh "
                              "to ~5k vertices: the meshes the model was trained on).")
DEVICE_OPTION = click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
PRECISION_OPTION = click.option(
    "--precision", type=click.Choice(["fp32", "bf16", "auto"]), default="fp32", show_default=True,
    help="Network and decoder precision. bf16: 1.6x faster (measured) where the hardware has native bf16 "
         "(AVX512-BF16 or AMX CPUs, CUDA GPUs from compute capability 8.0), slower where it is emulated, "
         "distances within ~1%. auto: bf16 only where it is native.")
FIELDS_OPTION = click.option(
    "--fields", "landmark_fields", type=click.Choice(["own", *LANDMARK_FIELDS]), default="own", show_default=True,
    callback=lambda ctx, param, value: None if value == "own" else value,
    help="A landmark model's fields by another solver than the one it was trained on (own). paths: real "
         "surface paths within 0.05% of exact; the default model's error falls from 0.253% to 0.144% on the "
         "validation meshes, its embed about 3x slower. exact: the exact solver's, the same error at about 6x the "
         "embed. Meshes only; docs/queries.md has the table.")
SIZE_OPTION = click.option("--size", default=480, show_default=True, help="Pixels across a rendered mesh (PNG).")
PRETRAINED_HELP = ("Use a model shipped in the package instead of CHECKPOINT: the most accurate one, or NAME "
                   f"({', '.join(repr(name) for name in PRETRAINED)}).")


def check_fields(config, fields) -> None:
    """UsageError where --fields asks a model for landmark fields it does not read (no landmarks, or a cloud's)."""
    if fields is not None and (not config.landmarks or config.points):
        what = "a point-cloud model" if config.points else "a model without landmarks"
        raise click.UsageError(f"--fields {fields}: {what} reads no mesh landmark fields")


def old_name(old: str, new: str, dest: str, **kwargs):
    """The name ``old`` of the option now called ``new``, kept for one version (renamed in 0.3.0, gone in
    0.4.0): hidden from --help, a warning on stderr when used; its value arrives as ``dest``, for
    :func:`either`."""
    def warn(ctx, param, value):
        if value is not None:
            click.echo(f"warning: {old} is now {new}; {old} goes in gegnn 0.4.0", err=True)
        return value

    return click.option(old, dest, hidden=True, callback=warn, **kwargs)


def either(new_value, old_value, new: str, old: str):
    """The option's value from its new or its old name (None where neither was given)."""
    if old_value is not None and new_value is not None:
        raise click.UsageError(f"{old} is the old name of {new}: give {new} alone")
    return new_value if old_value is None else old_value

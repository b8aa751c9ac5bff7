"""``seqrun init DIR``: a campaign folder of one's own, outside seqrun's source.

    seqrun init my-campaign && seqrun validate my-campaign
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from seqrun.cli.app import app
from seqrun.cli.common import fail
from seqrun.shipped import DEFAULT_ARM_NAME, shipped_dir

CONFIG_TEMPLATE = """\
# seqrun campaign (seqrun init). Sequences: sequences/, own poses: poses/ (they add to the
# shipped poses and override those of the same name). Reference: seqrun's README.

[campaign]
name = "{name}"
arm = "{arm}"               # a shipped arm (lwa3) or a file in this folder (arms/my-arm.yaml)

[bus]                       # as seqrun run -i/-c/-b; leave interface out for the simulator
# interface = "ixxat"
# channel = "0"
# bitrate = 1000000

[runs]
dir = "runs"                # run folders, relative to this folder

[ros]                       # run.mcap, the run as a ROS 2 bag (docs/ros2.md)
distribution = "jazzy"      # humble, jazzy or kilted

[sim]                       # the simulated arm of the dry run and every simulated run
# gripper_part_mm = 40      # the part between the jaws (unset: the sequence's grip's)
"""

#: Where the YAML files' ``# yaml-language-server: $schema=../docs/schema/...`` comments
#: point from sequences/, poses/ and arms/: the campaign gets its own copy of the schemas
#: (a campaign lives outside seqrun's source, whose docs/ they name otherwise).
SCHEMA_DIR = "docs/schema"

STARTER = """\
# yaml-language-server: $schema=../docs/schema/sequence.schema.json
name: First
description: >-
  A starter: start up a freshly powered-on arm and bring it to Totem, the working home.
steps:
  - include: startup.yaml
  - confirm: Is the space around the arm clear?
  - move: {pose: totem, velocity_scale: 0.5, label: Up to Totem}
  - checkpoint: {pose: totem, label: Check the end-effector is at Totem}
"""

POSES_README = """\
Pose files of this campaign (<name>.yaml). They add to seqrun's shipped poses (park, totem,
opsafe) and override a shipped pose of the same name (validation says so). Make one from
the arm with: seqrun pose save NAME -o poses/NAME.yaml
"""

GITIGNORE = "runs/\n.seqrun/\n"


@app.command("init")
def init_command(
    folder: Annotated[Path, typer.Argument(metavar="DIR", help="The campaign folder to "
                                                               "create (may exist).")],
    name: Annotated[str, typer.Option("--name", help="Campaign name (default: the folder's).")]
    = "",
    arm: Annotated[str, typer.Option("--arm", help="Shipped arm name or arm file relative "
                                                   "to the campaign.")] = DEFAULT_ARM_NAME,
) -> None:
    """Create a campaign folder: seqrun.toml, sequences/ with a starter, poses/, and the
    JSON Schemas the files name for editors (docs/schema/)."""
    import json

    from seqrun.service.campaigns import CONFIG_NAME
    from seqrun.service.formats import FORMATS, format_schema

    if folder.exists() and not folder.is_dir():
        fail(f"{folder} exists and is not a folder")
    if (folder / CONFIG_NAME).exists():
        fail(f"{folder / CONFIG_NAME} exists: {folder} is a campaign already")
    title = (name or folder.resolve().name).replace("\\", "\\\\").replace('"', '\\"')
    files = {
        CONFIG_NAME: CONFIG_TEMPLATE.format(name=title, arm=arm.replace('"', '\\"')),
        "sequences/startup.yaml": (shipped_dir("sequences") / "startup.yaml").read_text(
            encoding="utf-8"),
        "sequences/first.yaml": STARTER,
        "poses/README.md": POSES_README,
        ".gitignore": GITIGNORE,
        **{f"{SCHEMA_DIR}/{kind}.schema.json":
           json.dumps(format_schema(kind), indent=2, ensure_ascii=False) + "\n"
           for kind in FORMATS},
    }
    try:
        for relative, text in files.items():
            path = folder / relative
            if path.exists():
                continue  # never overwrite the user's files
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
    except OSError as exc:
        fail(f"cannot create the campaign in {folder}: {exc.strerror or exc}")
    typer.echo(f"campaign created in {folder}: {CONFIG_NAME}, sequences/first.yaml, "
               f"sequences/startup.yaml, poses/, {SCHEMA_DIR}/")
    typer.echo(f"next: seqrun validate {folder}")

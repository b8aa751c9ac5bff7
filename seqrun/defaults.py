"""Constants the command line needs before anything heavy is imported (``seqrun --help``
must not import pydantic, numpy, ruckig or python-can): default paths and exit codes."""

from __future__ import annotations

from pathlib import Path

#: The arm file and the pose directory, relative to the project root (the cwd).
DEFAULT_ARM = Path("arms/lwa3.yaml")
DEFAULT_POSES_DIR = Path("poses")
#: The pose static validation assumes the arm starts in: freshly powered on.
START_POSE = "park"

# Exit codes (the executor and every command share these).
EXIT_OK = 0
EXIT_INVALID = 1
EXIT_USAGE = 2
EXIT_FAULT = 3
EXIT_OPERATOR_ABORT = 130

"""Foxglove live: an arm session's data on a Foxglove WebSocket server (``foxglove-sdk``).

``seqrun run --foxglove[=PORT]`` and ``seqrun console --foxglove[=PORT]`` serve it on
127.0.0.1 (:mod:`.live`); docs/ros2.md says what an engineer sees and may call.
``foxglove-sdk`` is the optional extra ``seqrun[foxglove]``: without it the option is one
line saying how to install it.
"""

from __future__ import annotations

#: The port ``--foxglove`` alone serves on (the console's web page has 8765, Foxglove's
#: own default).
DEFAULT_PORT = 8766

#: What ``--foxglove`` says when foxglove-sdk is not installed.
MISSING = ("--foxglove needs foxglove-sdk, an optional part of seqrun: "
           "pip install 'seqrun[foxglove]'")


def available() -> bool:
    """foxglove-sdk can be imported."""
    import importlib.util

    return importlib.util.find_spec("foxglove") is not None

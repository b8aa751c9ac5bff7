"""``seqrun ros``: the arm session as a ROS 2 node (a face, like the console).

The node (:mod:`seqrun.ros.node`) needs ``rclpy`` and the message packages: the optional
extra ``seqrun[ros]`` (ROS 2 Jazzy's wheels from the package index) or a sourced ROS 2
installation. Importing this package never imports rclpy; :func:`missing` says what is not
there, in one line. docs/ros2-node.md.
"""

from __future__ import annotations

import re

#: The one line ``seqrun ros`` prints without the extra.
INSTALL_HINT = ("seqrun ros needs ROS 2's Python packages: pip install 'seqrun[ros]' "
                "(ROS 2 Jazzy wheels), or source a ROS 2 Jazzy installation first")

#: What the node cannot do without: rclpy and the messages it publishes and accepts.
REQUIRED_MODULES = ("rclpy", "sensor_msgs.msg", "trajectory_msgs.msg", "std_srvs.srv",
                    "std_msgs.msg", "geometry_msgs.msg")


def missing() -> str | None:
    """None when the node can start; else the one line saying how to install what it needs
    (naming the module that failed to import)."""
    import importlib

    for name in REQUIRED_MODULES:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            return f"{INSTALL_HINT} ({name}: {exc})"
    return None


def optional_module(name: str):
    """The module ``name`` when it can be imported (tf2_msgs, control_msgs: on a ROS host),
    else None."""
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError:
        return None


def ros_name(text: str) -> str:
    """``text`` as one ROS name token (letters, digits, underscores; not starting with a
    digit): an arm file's name ``lwa3`` stays ``lwa3``. The node's names and frames, and
    ``seqrun urdf``'s link names, are made with it."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", text).strip("_") or "arm"
    return name if not name[0].isdigit() else f"arm_{name}"

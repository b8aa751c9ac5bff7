"""The ``seqrun`` program validates without pydantic plugins, and without searching for them.

pydantic hands every validator it builds to the plugins that installed packages declare
(entry-point group ``pydantic``: tracing and logging tools). Finding them costs each
process the import of ``importlib.metadata`` (email, zipfile, csv, socket, ...) and a
read of every installed package's entry points: ~54 M instructions of ``seqrun validate``,
more than the checks of a sequence. And third-party code on the path of the arm's and the
sequences' validation is not wanted in a safety tool anyway.

So the program sets pydantic's own switch, ``PYDANTIC_DISABLE_PLUGINS``, unless the
environment sets it (as ``OPENBLAS_NUM_THREADS``: :mod:`seqrun.entry`), and while it
disables every plugin pydantic's plugin loader is replaced by :func:`get_plugins`, which
answers as the loader does then (no plugins) without importing what the search needs.
Setting the variable to anything else (``PYDANTIC_DISABLE_PLUGINS=`` for all plugins, or a
list of names to leave out) gives pydantic's own loader, also when changed at run time.
"""

from __future__ import annotations

import os
import sys
import types

#: The variable's values with which pydantic loads no plugin (pydantic/plugin/_loader.py).
DISABLING = ("__all__", "1", "true")
VARIABLE = "PYDANTIC_DISABLE_PLUGINS"
LOADER = "pydantic.plugin._loader"


def get_plugins() -> tuple:
    """pydantic's ``get_plugins`` while the variable disables every plugin: none."""
    if os.environ.get(VARIABLE) in DISABLING:
        return ()
    # plugins asked for after start-up: pydantic's own loader, from now on
    if getattr(sys.modules.get(LOADER), "get_plugins", None) is get_plugins:
        del sys.modules[LOADER]
    import importlib

    return importlib.import_module(LOADER).get_plugins()


def install() -> None:
    """Disable pydantic's plugins unless the environment says otherwise; then answer for
    its loader (before pydantic is imported: once it has loaded its own, nothing changes)."""
    os.environ.setdefault(VARIABLE, DISABLING[0])
    if os.environ[VARIABLE] not in DISABLING or LOADER in sys.modules:
        return
    loader = types.ModuleType(LOADER, "pydantic's plugin loader while every plugin is "
                                      "disabled (seqrun.pydantic_plugins)")
    loader.get_plugins = get_plugins  # type: ignore[attr-defined]
    loader.PYDANTIC_ENTRY_POINT_GROUP = "pydantic"  # type: ignore[attr-defined]
    sys.modules[LOADER] = loader

"""Simulator switches by name: ``ModuleOptions`` fields from strings or python-can kwargs.

The modules' unconfirmed behaviours (:class:`~seqrun.sim.module.ModuleOptions`) are
reachable wherever a simulator is made: ``seqrun sim serve`` flags, ``can.Bus(interface=
"seqrun-sim", home_ok_at_power_on=True)`` and ``--bus-kwargs home_ok_at_power_on=true``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from seqrun.sim.module import ModuleOptions

#: The switch names (``ModuleOptions`` fields).
SWITCHES = frozenset(f.name for f in dataclasses.fields(ModuleOptions))

_TRUE, _FALSE = {"1", "true", "yes", "on"}, {"0", "false", "no", "off"}


def _convert(name: str, value: Any, default: Any) -> Any:
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
        text = str(value).strip().lower()
        if text in _TRUE:
            return True
        if text in _FALSE:
            return False
        raise ValueError(f"{name}: expected true or false, got {value!r}")
    if isinstance(default, int):  # StateFlag fields and plain integers
        try:
            return type(default)(int(value))
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected an integer, got {value!r}") from None
    if isinstance(default, float):
        try:
            result = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected a number, got {value!r}") from None
        if not result >= 0:
            raise ValueError(f"{name}: must be >= 0, got {value!r}")
        return result
    return value


def module_options(switches: Mapping[str, Any],
                   base: ModuleOptions | None = None) -> ModuleOptions:
    """``base`` (default: today's behaviour) with the named switches changed.

    :raises ValueError: an unknown switch or a value of the wrong kind, saying which.
    """
    base = base or ModuleOptions()
    changes = {}
    for name, value in switches.items():
        if name not in SWITCHES:
            raise ValueError(f"unknown simulator option {name!r} "
                             f"(known: {', '.join(sorted(SWITCHES))})")
        changes[name] = _convert(name, value, getattr(base, name))
    return dataclasses.replace(base, **changes)


def pop_switches(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Remove and return the entries of ``kwargs`` that name a switch."""
    return {name: kwargs.pop(name) for name in list(kwargs) if name in SWITCHES}


def parse_module_options(spec: str, base: ModuleOptions | None = None) -> ModuleOptions:
    """``"framp_from_standstill, watchdog_timeout=0.1, ack_refused_motion=false"`` ->
    :class:`ModuleOptions` (``SEQRUN_SIM_OPTIONS``; a bare name means true; items separated
    by commas or spaces).

    :raises ValueError: an unknown option or a value of the wrong kind (one line).
    """
    switches: dict[str, Any] = {}
    for item in spec.replace(",", " ").split():
        name, sep, text = item.partition("=")
        switches[name.strip()] = text.strip() if sep else True
    return module_options(switches, base)

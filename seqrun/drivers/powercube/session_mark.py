"""The power-session mark: a number left in the modules' RAM that a power cycle erases.

seqrun must know whether the modules were powered off since the operator confirmed their
zero (they take their encoder zero where they were powered off). HOME_OK cannot say it:
modules may power on homed, and ``seqrun home`` sets it. So once the zero is confirmed
the driver leaves a mark in every module's *actual* homing velocity, FHomeVel (0x64, R/W),
whose power-on value is the stored DefHomeVel (0x0F, R): the mark is the exclusive-or of
the two float32 bit patterns, in the low :data:`MARK_BITS` bits of the mantissa (a change
of at most 0.05 % of a velocity a PRL module does not use to home: its encoders are
absolute).

A mark is only believed while FHomeVel differs from DefHomeVel: a firmware that saved the
written value as its stored one (never seen; the simulator's ``fhome_vel_saved_on_write``)
would read back "no mark", and the zero is asked again: the safe side. Pure: no I/O.
"""

from __future__ import annotations

import struct

from seqrun.drivers.base import SESSION_MARK_LIMIT

#: How many low mantissa bits carry the mark (marks are 1 .. 2**MARK_BITS - 1).
MARK_BITS = 12
MARK_LIMIT = 1 << MARK_BITS
assert MARK_LIMIT == SESSION_MARK_LIMIT, "every mark the service layer draws must fit"


def _bits(value: float) -> int:
    return int(struct.unpack("<I", struct.pack("<f", float(value)))[0])


def _value(bits: int) -> float:
    return float(struct.unpack("<f", struct.pack("<I", bits & 0xFFFFFFFF))[0])


def marked_velocity(stored: float, mark: int) -> float:
    """The FHomeVel that carries ``mark`` on a module whose DefHomeVel is ``stored``."""
    if not 0 < mark < MARK_LIMIT:
        raise ValueError(f"a session mark is 1 .. {MARK_LIMIT - 1}, got {mark}")
    return _value(_bits(stored) ^ mark)


def mark_of(actual: float, stored: float) -> int | None:
    """The mark FHomeVel ``actual`` carries over DefHomeVel ``stored``; None when it
    carries none (the values are equal: a power-on, or a firmware that saved it) or
    differ by more than a mark (somebody else set the homing velocity)."""
    difference = _bits(actual) ^ _bits(stored)
    if difference == 0 or difference >= MARK_LIMIT:
        return None
    return difference

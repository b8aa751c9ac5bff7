"""Exact length on the wire of a classic CAN data frame, and how long it occupies the bus.

The simulator needs this to make a 1 Mbit/s bus as slow as the real one: an 8-byte
acknowledge is not "about 100 µs", it is 111 to 135 bit times depending on how many
stuff bits its identifier, data and CRC happen to need. Everything here is pure.

Layout of a CAN 2.0A (11-bit identifier) data frame, in bit times::

    SOF 1 | ID 11 | RTR 1 | IDE 1 | r0 1 | DLC 4 | DATA 8n | CRC 15      <- bit stuffed
    CRC delimiter 1 | ACK slot 1 | ACK delimiter 1 | EOF 7 | intermission 3

A CAN 2.0B (29-bit identifier) frame has ``ID 11 | SRR 1 | IDE 1 | ID 18 | RTR 1 | r1 1 |
r0 1`` in place of ``ID | RTR | IDE | r0``. Remote frames carry a DLC but no data field.
Stuffing: after five consecutive equal bits the transmitter inserts one bit of the
opposite level, which itself counts towards the next run; it applies from SOF to the
end of the CRC sequence. The CRC-15 (polynomial 0x4599) is computed over the unstuffed
bits from SOF to the end of the data field.

Not covered: CAN FD, error and overload frames, retransmissions, bus-off.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable

CRC15_POLYNOMIAL = 0x4599
#: CRC delimiter, ACK slot, ACK delimiter and the 7 bits of end of frame.
TRAILER_BITS = 1 + 1 + 1 + 7
#: Intermission between frames (the interframe space on an otherwise idle bus).
INTERMISSION_BITS = 3


def _bits(value: int, width: int) -> list[int]:
    return [(value >> shift) & 1 for shift in range(width - 1, -1, -1)]


def crc15(bits: Iterable[int]) -> int:
    """CRC-15/CAN of a bit sequence (most significant bit first), as the controller computes it."""
    crc = 0
    for bit in bits:
        feedback = bit ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if feedback:
            crc ^= CRC15_POLYNOMIAL
    return crc


def unstuffed_bits(can_id: int, data: bytes = b"", *, extended: bool = False,
                   remote: bool = False, dlc: int | None = None) -> list[int]:
    """The bits from SOF to the end of the CRC sequence, before stuffing (0 = dominant).

    :param dlc: only for remote frames, which announce a length without sending data.
    :raises ValueError: identifier out of range, more than 8 data bytes, data in a remote frame.
    """
    data = bytes(data)
    if len(data) > 8:
        raise ValueError(f"a classic CAN frame carries at most 8 data bytes, got {len(data)}")
    if remote and data:
        raise ValueError("a remote frame carries no data bytes")
    if dlc is None:
        dlc = len(data)
    elif not remote and dlc != len(data):
        raise ValueError(f"dlc {dlc} does not match {len(data)} data bytes")
    if not 0 <= dlc <= 8:
        raise ValueError(f"dlc must be 0..8, got {dlc}")
    rtr = 1 if remote else 0
    bits = [0]  # SOF
    if extended:
        if not 0 <= can_id < 1 << 29:
            raise ValueError(f"extended CAN id must be 0..0x1FFFFFFF, got {can_id:#x}")
        bits += _bits(can_id >> 18, 11) + [1, 1]  # base id, SRR, IDE (both recessive)
        bits += _bits(can_id & 0x3FFFF, 18) + [rtr, 0, 0]  # extension, RTR, r1, r0
    else:
        if not 0 <= can_id <= 0x7FF:
            raise ValueError(f"standard CAN id must be 0..0x7FF, got {can_id:#x}")
        bits += _bits(can_id, 11) + [rtr, 0, 0]  # RTR, IDE, r0
    bits += _bits(dlc, 4)
    for byte in data:
        bits += _bits(byte, 8)
    return bits + _bits(crc15(bits), 15)


def stuff_bit_count(bits: Iterable[int]) -> int:
    """How many stuff bits a transmitter inserts into ``bits``."""
    count = 0
    run_level = None
    run_length = 0
    for bit in bits:
        if bit == run_level:
            run_length += 1
        else:
            run_level, run_length = bit, 1
        if run_length == 5:
            count += 1
            # The inserted bit has the opposite level and starts the next run.
            run_level, run_length = 1 - bit, 1
    return count


def frame_bit_length(can_id: int, data: bytes = b"", *, extended: bool = False,
                     remote: bool = False, dlc: int | None = None,
                     intermission: bool = True) -> int:
    """Bit times a data (or remote) frame occupies, stuff bits included.

    With ``intermission=True`` (the default) the 3-bit interframe space is counted, so the
    sum over back-to-back frames is the bus time they need.
    """
    # Same result as counting over unstuffed_bits() (the tests compare them), but on
    # integers, a byte at a time: the simulator computes this for every frame whose data
    # changes (positions in acks and setpoints, about every other frame of a move).
    data = bytes(data)
    n = len(data)
    if n > 8:
        raise ValueError(f"a classic CAN frame carries at most 8 data bytes, got {n}")
    if remote and data:
        raise ValueError("a remote frame carries no data bytes")
    if dlc is None:
        dlc = n
    elif not remote and dlc != n:
        raise ValueError(f"dlc {dlc} does not match {n} data bytes")
    if not 0 <= dlc <= 8:
        raise ValueError(f"dlc must be 0..8, got {dlc}")
    rtr = 1 if remote else 0
    if extended:
        if not 0 <= can_id < 1 << 29:
            raise ValueError(f"extended CAN id must be 0..0x1FFFFFFF, got {can_id:#x}")
        # SOF, base id, SRR, IDE, extension, RTR, r1, r0, DLC
        header = (((((can_id >> 18) << 2 | 0b11) << 18 | (can_id & 0x3FFFF)) << 3
                   | rtr << 2) << 4) | dlc
        width = 39
    else:
        if not 0 <= can_id <= 0x7FF:
            raise ValueError(f"standard CAN id must be 0..0x7FF, got {can_id:#x}")
        header = ((can_id << 3 | rtr << 2) << 4) | dlc  # SOF, id, RTR, IDE, r0, DLC
        width = 19
    # CRC and stuffing in one pass over the data bytes, from their state after the header.
    crc, count, state = _after_header(header, width)
    crc_table, stuff_table = _CRC15_TABLE, _stuff_table
    for byte in data:
        crc = ((crc << 8) & 0x7FFF) ^ crc_table[((crc >> 7) ^ byte) & 0xFF]
        entry = stuff_table[state | byte]
        if not entry:
            entry = stuff_table[state | byte] = _stuff_step(state >> 8, byte, 8)
        count += entry >> 16
        state = entry & 0xFF00
    # The CRC sequence: its first 7 bits, then its last 8.
    entry = _stuff_partial(state, crc >> 8, 7)
    count += entry >> 16
    state = entry & 0xFF00
    entry = stuff_table[state | crc & 0xFF]
    if not entry:
        entry = stuff_table[state | crc & 0xFF] = _stuff_step(state >> 8, crc & 0xFF, 8)
    length = width + 8 * n + 15 + count + (entry >> 16) + TRAILER_BITS
    return length + (INTERMISSION_BITS if intermission else 0)


def _crc15_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = ((crc << 1) ^ CRC15_POLYNOMIAL) if crc & 0x4000 else crc << 1
            crc &= 0x7FFF
        table.append(crc)
    return table


#: CRC-15 of one byte fed MSB first, for the table-driven update in frame_bit_length.
_CRC15_TABLE = _crc15_table()


# Stuffing a byte at a time. A transmitter's stuffing state between bits is the level and
# length (1..4) of the current run: state index 1 + 4 * level + length - 1, or 0 before
# the first bit (a run of 5 never lasts: its stuff bit starts a run of 1 of the other
# level). A table entry, for (state, byte), packs the stuff bits that byte needs and the
# state after it: stuff_bits << 16 | state << 8; it is filled on first use (0: not yet;
# no byte ends in state 0).
_STUFF_STATES = 9
_stuff_table = [0] * (_STUFF_STATES << 8)
#: The same for fewer bits, by (state << 4 | width) << 8 | bits.
_stuff_partials: dict[int, int] = {}


def _stuff_step(state: int, bits: int, width: int) -> int:
    """The table entry for ``width`` bits (most significant first) sent in ``state``."""
    level, length = ((state - 1) >> 2, ((state - 1) & 3) + 1) if state else (-1, 0)
    count = 0
    for shift in range(width - 1, -1, -1):
        bit = bits >> shift & 1
        if bit == level:
            length += 1
        else:
            level, length = bit, 1
        if length == 5:
            count += 1
            level, length = 1 - bit, 1  # the stuff bit starts the next run
    return count << 16 | (1 + 4 * level + length - 1) << 8


def _stuff_partial(state: int, bits: int, width: int) -> int:
    """:func:`_stuff_step` entry for ``width`` (< 8) bits in ``state`` (shifted: << 8)."""
    key = (state >> 4 | width) << 8 | bits
    entry = _stuff_partials.get(key)
    if entry is None:
        entry = _stuff_partials[key] = _stuff_step(state >> 8, bits, width)
    return entry


@functools.lru_cache(maxsize=4096)
def _after_header(header: int, width: int) -> tuple[int, int, int]:
    """(CRC-15, stuff bits, stuffing state << 8) after the ``width`` bits of ``header``
    (SOF to DLC)."""
    crc = crc15(_bits(header, width))
    count, state = 0, 0
    first = width & 7  # a partial chunk first, then whole bytes
    if first:
        entry = _stuff_partial(0, header >> (width - first), first)
        count, state = entry >> 16, entry & 0xFF00
    for shift in range(width - first - 8, -1, -8):
        entry = _stuff_step(state >> 8, header >> shift & 0xFF, 8)
        count += entry >> 16
        state = entry & 0xFF00
    return crc, count, state


def frame_time(can_id: int, data: bytes = b"", bitrate: int = 1_000_000, *,
               extended: bool = False, remote: bool = False, dlc: int | None = None,
               intermission: bool = True) -> float:
    """Seconds the frame occupies a bus at ``bitrate`` bit/s (see :func:`frame_bit_length`)."""
    if bitrate <= 0:
        raise ValueError(f"bitrate must be positive, got {bitrate}")
    bits = frame_bit_length(can_id, data, extended=extended, remote=remote, dlc=dlc,
                            intermission=intermission)
    return bits / bitrate


def bit_length_bounds(dlc: int, *, extended: bool = False) -> tuple[int, int]:
    """(fewest, most) bit times of any data frame with ``dlc`` bytes, intermission included.

    The most assumes a stuff bit after every fourth bit of the stuffed region, the usual
    worst-case bound (135 bits for an 8-byte standard frame).
    """
    stuffed_region = (54 if extended else 34) + 8 * dlc
    base = stuffed_region + TRAILER_BITS + INTERMISSION_BITS
    return base, base + (stuffed_region - 1) // 4

"""Frame bit lengths checked against known values and an independent, naive reference."""

from __future__ import annotations

import random
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from seqrun.powercube.can_timing import (
    bit_length_bounds,
    crc15,
    frame_bit_length,
    frame_time,
    stuff_bit_count,
    unstuffed_bits,
)


def _bitstring(value: int, width: int) -> str:
    return format(value, f"0{width}b")


def _reference_crc(bits: str) -> int:
    """CRC as polynomial long division of bits * x^15 by x^15 + 0x4599 (textbook form)."""
    dividend = int(bits + "0" * 15, 2) if bits else 0
    divisor = (1 << 15) | 0x4599
    for shift in range(len(bits) - 1, -1, -1):
        if dividend >> (shift + 15) & 1:
            dividend ^= divisor << shift
    return dividend


def _reference_length(can_id: int, data: bytes) -> int:
    """Standard data frame length, written from the frame diagram without shared code."""
    head = "0" + _bitstring(can_id, 11) + "000" + _bitstring(len(data), 4)
    head += "".join(_bitstring(b, 8) for b in data)
    region = head + _bitstring(_reference_crc(head), 15)
    stuffed = ""
    for bit in region:
        stuffed += bit
        if re.search(r"(00000|11111)$", stuffed):
            stuffed += "1" if bit == "0" else "0"
    return len(stuffed) + 10 + 3


def test_crc15_check_value_of_the_crc_catalogue():
    # CRC-15/CAN: check value for the ASCII string "123456789" is 0x059E.
    bits = [int(b) for b in "".join(_bitstring(c, 8) for c in b"123456789")]
    assert crc15(bits) == 0x059E


def test_all_dominant_frame_has_known_length():
    # id 0, no data: 34 dominant bits (CRC of zeros is zero) -> 6 stuff bits.
    bits = unstuffed_bits(0, b"")
    assert bits == [0] * 34
    assert stuff_bit_count(bits) == 6
    assert frame_bit_length(0, b"") == 34 + 6 + 10 + 3
    assert frame_bit_length(0, b"", intermission=False) == 50


def test_stuff_bit_starts_the_next_run():
    # 5 zeros -> stuff 1; then 4 ones make a run of 5 with the stuff bit -> second stuff bit.
    assert stuff_bit_count([0, 0, 0, 0, 0, 1, 1, 1, 1]) == 2
    assert stuff_bit_count([0, 0, 0, 0, 1, 1, 1, 1]) == 0
    assert stuff_bit_count([1] * 10) == 2


def test_frame_without_any_stuff_bit_reaches_the_lower_bound():
    assert frame_bit_length(0x086, bytes([0x55] * 8)) == 111 == bit_length_bounds(8)[0]


def test_worst_case_bound_of_an_8_byte_frame():
    assert bit_length_bounds(8) == (111, 135)
    assert bit_length_bounds(0) == (47, 55)
    assert bit_length_bounds(8, extended=True) == (131, 160)
    # A heavily stuffed frame found by search: 20 stuff bits.
    assert frame_bit_length(0x02F, bytes([0x3C] * 8)) == 131


def test_powercube_frames():
    # GetExtended 0x62 request (2 bytes) and its 8-byte acknowledge, as used by a refresh.
    assert frame_bit_length(0x0C1, bytes.fromhex("0A62")) == 67
    assert frame_bit_length(0x0A1, bytes.fromhex("0A623333333F0000")) == 116
    assert frame_time(0x0C1, bytes.fromhex("0A62"), 1_000_000) == pytest.approx(67e-6)
    assert frame_time(0x0C1, bytes.fromhex("0A62"), 500_000) == pytest.approx(134e-6)


def test_matches_independent_reference_on_random_frames():
    rng = random.Random(1234)
    for _ in range(400):
        can_id = rng.randrange(0x800)
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
        assert frame_bit_length(can_id, data) == _reference_length(can_id, data)
        fewest, most = bit_length_bounds(len(data))
        assert fewest <= frame_bit_length(can_id, data) <= most


def test_monotonic_in_dlc_for_same_content_pattern():
    # Fewer/most bounds grow by 8 (+2 stuff) per byte; real frames with the same id and
    # byte pattern grow with every extra byte.
    for pattern in (0x00, 0xFF, 0x55, 0xA5):
        lengths = [frame_bit_length(0x0A3, bytes([pattern] * n)) for n in range(9)]
        assert lengths == sorted(lengths) and len(set(lengths)) == 9
    lows = [bit_length_bounds(n)[0] for n in range(9)]
    assert lows == [47 + 8 * n for n in range(9)]


def test_extended_and_remote_frames():
    # Extended: 20 more bits in the stuffed region than the standard frame layout.
    bits = unstuffed_bits(0, b"", extended=True)
    assert len(bits) == 54
    remote = unstuffed_bits(0x123, b"", remote=True, dlc=8)
    assert len(remote) == 34 and remote[12] == 1  # RTR recessive, no data field


@given(st.booleans(), st.integers(0, (1 << 29) - 1), st.binary(max_size=8),
       st.booleans(), st.integers(0, 8))
def test_bit_length_counts_the_stuff_bits_of_the_bit_list(extended, raw_id, data, remote,
                                                          remote_dlc):
    # The table-driven count of frame_bit_length against the bit-by-bit one, for standard,
    # extended and remote frames alike.
    can_id = raw_id if extended else raw_id & 0x7FF
    if remote:
        data, dlc = b"", remote_dlc
    else:
        dlc = None
    bits = unstuffed_bits(can_id, data, extended=extended, remote=remote, dlc=dlc)
    expected = len(bits) + stuff_bit_count(bits) + 10
    assert frame_bit_length(can_id, data, extended=extended, remote=remote, dlc=dlc,
                            intermission=False) == expected
    assert frame_bit_length(can_id, data, extended=extended, remote=remote, dlc=dlc) == (
        expected + 3)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"can_id": 0x800, "data": b""}, "standard CAN id must be 0..0x7FF"),
        ({"can_id": 1, "data": bytes(9)}, "at most 8 data bytes"),
        ({"can_id": 1, "data": b"\x01", "remote": True}, "no data bytes"),
        ({"can_id": 1 << 29, "data": b"", "extended": True}, "extended CAN id"),
    ],
)
def test_rejects_impossible_frames(kwargs, message):
    with pytest.raises(ValueError, match=message):
        frame_bit_length(**kwargs)


def test_rejects_non_positive_bitrate():
    with pytest.raises(ValueError, match="bitrate must be positive"):
        frame_time(1, b"", 0)

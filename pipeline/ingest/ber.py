"""The BER length of a KLV triplet (SMPTE 336 / ITU-T X.690 definite form), as ST 0601 packets, EG 0104 sets
and their items all carry it: one byte < 0x80 is the length; 0x81-0x84 say that 1-4 big-endian bytes follow."""

from __future__ import annotations

MAX_LENGTH_BYTES = 4  # a longer long form (or 0x80, the indefinite form) is not a KLV length: malformed


def ber_length(data: bytes, pos: int) -> tuple[int, int] | None:
    """(length, position after the length field) of the BER length at data[pos], or None when it is malformed.

    When the field itself is cut off by the end of `data`, the position returned is past len(data) (and the
    length 0): callers tell "cut off" from "malformed" that way. O(1)."""
    if pos >= len(data):
        return 0, pos + 1
    first = data[pos]
    if first < 0x80:
        return first, pos + 1
    nb = first & 0x7F
    if nb == 0 or nb > MAX_LENGTH_BYTES:
        return None
    if pos + 1 + nb > len(data):
        return 0, pos + 1 + nb
    return int.from_bytes(data[pos + 1:pos + 1 + nb], "big"), pos + 1 + nb

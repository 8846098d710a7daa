"""The BER length of a KLV triplet (SMPTE 336 / ITU-T X.690 definite form), as ST 0601 packets, EG 0104 sets
and their items all carry it: one byte < 0x80 is the length; 0x81-0x84 say that 1-4 big-endian bytes follow.
Decoded by stanag4609 (`klv.decode_ber_length`, the library that decodes the ST 0601 sets); this module only
turns its exceptions into what the packet scans count: malformed or cut off."""

from __future__ import annotations

MAX_LENGTH_BYTES = 4  # a longer long form (or 0x80, the indefinite form) is not a KLV length: malformed


def ber_length(data: bytes, pos: int) -> tuple[int, int] | None:
    """(length, position after the length field) of the BER length at data[pos], or None when it is malformed.

    When the field itself is cut off by the end of `data`, the position returned is past len(data) (and the
    length 0): callers tell "cut off" from "malformed" that way. O(1)."""
    from stanag4609.errors import DecodeError, NeedMoreData  # imported on first use: the package takes ~0.5 s
    from stanag4609.klv import decode_ber_length

    try:
        length, used = decode_ber_length(data, pos, canonical=False, max_octets=MAX_LENGTH_BYTES)
    except NeedMoreData:
        return 0, len(data) + 1
    except DecodeError:
        return None
    return length, pos + used

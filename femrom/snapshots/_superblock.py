"""Recover an HDF5 file whose SWMR writer was killed: clear its "open for write" flags.

An HDF5 file written with ``libver="latest"`` has a version-3 superblock
whose *file consistency flags* say "open for write" (bit 0) and "open for
SWMR write" (bit 2) while a writer has it open. A writer that is killed never
clears them, and the library then refuses to open the file for writing again
(readers in SWMR mode still can). This module does what the HDF Group's
``h5clear -s --increment`` tool does, for the one superblock layout femrom
writes:

- check the superblock checksum (so a damaged or foreign superblock is never
  rewritten),
- clear the flags,
- raise the stored end-of-file address to the real file size, so that new
  allocations never land on chunks a killed SWMR writer had already written
  past the address it last recorded,
- write the 4-byte checksum again.

Superblock version 2/3 layout (HDF5 File Format Specification, section II.A,
"Superblock Version 2"): signature (8 bytes), version (1), size of offsets
(1), size of lengths (1), consistency flags (1), base address, extension
address, end-of-file address, root object header address (``size of
offsets`` bytes each), checksum (4). The checksum is Bob Jenkins' lookup3
``hashlittle`` with initial value 0 (public domain, 2006), which the format
specification names for all its metadata checksums.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass

from femrom._errors import FemromValueError

SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Where the library looks for the superblock: 0, then 512, 1024, 2048, ... (user block sizes).
_SEARCH_OFFSETS = (0, 512, 1024, 2048, 4096, 8192, 16384, 32768, 65536)
_WRITE_FLAGS = 0b101  # bit 0: open for write; bit 2: open for SWMR write
_MASK = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _MASK


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` of ``data`` (a 32-bit unsigned int)."""
    length = len(data)
    a = b = c = (0xDEADBEEF + length + initval) & _MASK
    pos = 0
    while length - pos > 12:
        a = (a + int.from_bytes(data[pos:pos + 4], "little")) & _MASK
        b = (b + int.from_bytes(data[pos + 4:pos + 8], "little")) & _MASK
        c = (c + int.from_bytes(data[pos + 8:pos + 12], "little")) & _MASK
        # mix(a, b, c)
        a = (a - c) & _MASK; a ^= _rot(c, 4); c = (c + b) & _MASK
        b = (b - a) & _MASK; b ^= _rot(a, 6); a = (a + c) & _MASK
        c = (c - b) & _MASK; c ^= _rot(b, 8); b = (b + a) & _MASK
        a = (a - c) & _MASK; a ^= _rot(c, 16); c = (c + b) & _MASK
        b = (b - a) & _MASK; b ^= _rot(a, 19); a = (a + c) & _MASK
        c = (c - b) & _MASK; c ^= _rot(b, 4); b = (b + a) & _MASK
        pos += 12
    tail = data[pos:]
    if not tail:
        return c
    tail = tail + bytes(12 - len(tail))  # the missing bytes add nothing
    a = (a + int.from_bytes(tail[0:4], "little")) & _MASK
    b = (b + int.from_bytes(tail[4:8], "little")) & _MASK
    c = (c + int.from_bytes(tail[8:12], "little")) & _MASK
    # final(a, b, c)
    c ^= b; c = (c - _rot(b, 14)) & _MASK
    a ^= c; a = (a - _rot(c, 11)) & _MASK
    b ^= a; b = (b - _rot(a, 25)) & _MASK
    c ^= b; c = (c - _rot(b, 16)) & _MASK
    a ^= c; a = (a - _rot(c, 4)) & _MASK
    b ^= a; b = (b - _rot(a, 14)) & _MASK
    c ^= b; c = (c - _rot(b, 24)) & _MASK
    return c


@dataclass(frozen=True)
class Superblock:
    """The fields of a version-2/3 superblock that recovery needs."""

    offset: int          # where the superblock starts in the file
    version: int
    offset_size: int
    flags: int
    eof_address: int
    raw: bytes           # the whole superblock, checksum included

    @property
    def open_for_write(self) -> bool:
        return bool(self.flags & _WRITE_FLAGS)


class SuperblockError(FemromValueError):
    """The file has no readable version-2/3 superblock."""


def read_superblock(path) -> Superblock:
    """Find and check the superblock of ``path``.

    Raises
    ------
    SuperblockError
        No HDF5 signature, a version other than 2 or 3, or a bad checksum.
    """
    with open(path, "rb") as fh:
        for offset in _SEARCH_OFFSETS:
            fh.seek(offset)
            head = fh.read(12)
            if len(head) < 12:
                break
            if head[:8] != SIGNATURE:
                continue
            version, offset_size, _, flags = head[8:12]
            if version not in (2, 3):
                raise SuperblockError(f"superblock version {version} (femrom writes version 3)")
            if offset_size not in (2, 4, 8):
                raise SuperblockError(f"unsupported size of offsets {offset_size}")
            size = 12 + 4 * offset_size + 4
            fh.seek(offset)
            raw = fh.read(size)
            if len(raw) < size:
                raise SuperblockError("truncated superblock")
            stored = int.from_bytes(raw[-4:], "little")
            if lookup3(raw[:-4]) != stored:
                raise SuperblockError("superblock checksum mismatch")
            eof_at = 12 + 2 * offset_size
            eof = int.from_bytes(raw[eof_at:eof_at + offset_size], "little")
            return Superblock(offset, version, offset_size, flags, eof, raw)
    raise SuperblockError("no HDF5 signature")


def clear_write_flags(path) -> bool:
    """Clear the "open for (SWMR) write" flags left by a killed writer.

    Also raises the recorded end-of-file address to the file's size. Only
    call this when no process is writing the file.

    Returns
    -------
    bool
        Whether the flags were set (and are now cleared).
    """
    block = read_superblock(path)
    if not block.open_for_write:
        return False
    raw = bytearray(block.raw)
    raw[11] = block.flags & ~_WRITE_FLAGS & 0xFF
    size = os.path.getsize(path)
    eof_at = 12 + 2 * block.offset_size
    if size - block.offset > block.eof_address:  # addresses are relative to the base (= offset)
        raw[eof_at:eof_at + block.offset_size] = (size - block.offset).to_bytes(block.offset_size,
                                                                                 "little")
    raw[-4:] = struct.pack("<I", lookup3(bytes(raw[:-4])))
    with open(path, "r+b") as fh:
        fh.seek(block.offset)
        fh.write(bytes(raw))
        fh.flush()
        os.fsync(fh.fileno())
    return True

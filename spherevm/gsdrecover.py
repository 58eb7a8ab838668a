"""What a damaged or cut-short GSD file still holds: the frames written before the damage.

A GSD file (gsd 2.x layout, ``gsd/gsd.c``) is a 256-byte header, data chunks, a name list and an
index of 32-byte entries (frame, rows, location, columns, name id, type); the header points to the
current index and name list. gsd appends each frame's data at the end of the file, then its index
entries; when the index or the name list is full, gsd copies it, larger, to the end of the file and
points the header there, leaving the old copy in place. A file cut short (an interrupted copy, a
full disk) loses the current index or the end of the data, and gsd then refuses the whole file,
although every frame written before the cut is still on disk.

:func:`open_intact` finds the fullest surviving copy of the index and of the name list (every copy
begins with the bytes the first copy begins with), keeps the leading frames whose entries, names
and data all lie inside the file, and gives gsd's own pure-Python reader (``gsd.pygsd.GSDFile``) a
read-only view of the file whose header points to them; :func:`copy_frames` writes frames to a new
file with ``gsd.fl``. Nothing here writes to the damaged file.
"""
from __future__ import annotations

import io
import mmap
import os

import numpy as np

HEADER = 256                       # sizeof(struct gsd_header)
ENTRY = np.dtype([("frame", "<u8"), ("N", "<u8"), ("location", "<i8"), ("M", "<u4"),
                  ("id", "<u2"), ("type", "u1"), ("flags", "u1")])   # struct gsd_index_entry, 32 bytes
FIRST_NAMES = HEADER + 128 * ENTRY.itemsize   # the first name list follows the first index (128 entries)
MAGIC = 0x65DF65DF65DF65DF
_ITEMSIZE = np.zeros(256, dtype=np.int64)     # bytes per item by gsd type id (0: not a type)
_ITEMSIZE[1:12] = (1, 2, 4, 8, 1, 2, 4, 8, 4, 8, 1)


def _header(data):
    from gsd import pygsd
    return pygsd.gsd_header._make(pygsd.gsd_header_struct.unpack(bytes(data[:HEADER])))


def _chunk_ends(entries):
    """End offset of each entry's data (-1 where the entry is not plausible)."""
    size = _ITEMSIZE[entries["type"]]
    ok = (size > 0) & (entries["M"] > 0) & (entries["flags"] == 0) & (entries["N"] < 2 ** 40) \
        & (entries["M"] < 2 ** 20) & (entries["location"] >= HEADER)
    ends = entries["location"] + entries["N"].astype(np.int64) * entries["M"].astype(np.int64) * size
    return np.where(ok, ends, -1)


def whole(path) -> bool:
    """Whether every entry of the current index of the GSD file ``path`` is readable (a known type,
    its data inside the file) and the frames never decrease along the index (gsd checks only some
    entries when it opens a file, and a lookup in an index out of order can miss a chunk)."""
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        head = _header(f.read(HEADER))
        if head.index_location + head.index_allocated_entries * ENTRY.itemsize > size:
            return False
        f.seek(head.index_location)
        entries = np.fromfile(f, dtype=ENTRY, count=head.index_allocated_entries)
    entries = entries[entries["location"] != 0]
    ends = _chunk_ends(entries)
    return bool((ends > 0).all() and (ends <= size).all() and (np.diff(entries["frame"].astype(np.int64)) >= 0).all())


def _names(data, start, size):
    """The names of the name-list copy at ``start`` (a name cut by the end of the file is left out)."""
    end = data.find(b"\0\0", start, size)
    raw = bytes(data[start:size if end < 0 else end + 1])
    parts = raw.split(b"\0")
    out = []
    for part in parts[:-1]:           # the last part is not NUL-terminated (or is empty)
        if not part:
            break
        try:
            out.append(part.decode("utf-8"))
        except UnicodeDecodeError:
            break
    return out


def _entries(data, start, size):
    """The entries of the index copy at ``start``, up to its first empty slot or the end of the file,
    and whether an empty slot ended them (then every frame they list is listed whole)."""
    parts, at, block = [], start, 4096
    while at + ENTRY.itemsize <= size:
        count = min(block, (size - at) // ENTRY.itemsize)
        part = np.frombuffer(data[at:at + count * ENTRY.itemsize], dtype=ENTRY)
        zero = np.flatnonzero(part["location"] == 0)
        if len(zero):
            parts.append(part[:zero[0]])
            return np.concatenate(parts), True
        parts.append(part)
        at += count * ENTRY.itemsize
    return (np.concatenate(parts) if parts else np.zeros(0, dtype=ENTRY)), False


def _frames(data, start, size, n_names):
    """(intact frame count, their entries) read from the index copy at ``start``."""
    entries, clean = _entries(data, start, size)
    ends = _chunk_ends(entries)
    frames = entries["frame"].astype(np.int64)
    bad = (ends < 0) | (ends > size) | (entries["id"] >= n_names) | (frames < np.maximum.accumulate(frames))
    first_bad = np.flatnonzero(bad)
    if len(first_bad):
        j = int(first_bad[0])             # the frames before the first entry that cannot be read
        k = 0 if j == 0 else min(int(frames[j]), int(frames[j - 1]) + 1)
    elif len(entries) == 0:
        k = 0
    else:                             # the last listed frame is whole only if the copy ends cleanly
        k = int(frames[-1]) + 1 if clean else int(frames[-1])
    return k, entries[frames < k]


def _copies(data, size, starts, width):
    """Offsets of the copies of a block (an index or a name list) that begins at one of ``starts``:
    those starts inside the file, and every place where the first used one's first ``width(start)``
    bytes appear again (``width`` is 0 for a block not used yet)."""
    found = {s for s in starts if s < size}
    used = [s for s in sorted(found) if width(s) > 0]
    if used:
        pattern = data[used[0]:used[0] + width(used[0])]
        at = data.find(pattern, HEADER, size)
        while at >= 0:
            found.add(at)
            at = data.find(pattern, at + 1, size)
    return sorted(found)


class _View(io.RawIOBase):
    """The damaged file seen through a new header that points to an index and a name list placed
    after its end (``tail``); nothing is written."""

    def __init__(self, path, header, size, tail):
        super().__init__()
        self.name = os.fspath(path)
        self._file = open(path, "rb")
        self._header, self._size, self._tail = header, size, tail
        self._pos = 0

    def readable(self):
        return True

    def seekable(self):
        return True

    def seek(self, offset, whence=0):
        self._pos = (offset, self._pos + offset, self._size + len(self._tail) + offset)[whence]
        return self._pos

    def tell(self):
        return self._pos

    def read(self, n=-1):
        end = self._size + len(self._tail) if n is None or n < 0 else self._pos + n
        out = bytearray()
        while self._pos < end:
            if self._pos < HEADER:
                piece = self._header[self._pos:min(end, HEADER)]
            elif self._pos < self._size:
                self._file.seek(self._pos)
                piece = self._file.read(min(end, self._size) - self._pos)
            else:
                piece = self._tail[self._pos - self._size:end - self._size]
            if not piece:
                break
            out += piece
            self._pos += len(piece)
        return bytes(out)

    def close(self):
        self._file.close()
        super().close()


def open_intact(path):
    """The leading frames of the GSD file ``path`` that are intact, as a ``gsd.pygsd.GSDFile`` (the
    read interface of ``gsd.fl``); None when it has no GSD 2.x header."""
    from gsd import pygsd
    size = os.path.getsize(path)
    if size < HEADER:
        return None
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        head = _header(data)
        if head.magic != MAGIC or head.gsd_version >> 16 != 2:
            return None

        def name_width(at):
            first = _names(data, at, min(size, at + 1024))
            return len(first[0].encode("utf-8")) + 1 if first else 0

        def entry_width(at):
            return ENTRY.itemsize if at + ENTRY.itemsize <= size and any(data[at + 16:at + 24]) else 0

        names = max((_names(data, at, size) for at in
                     _copies(data, size, (head.namelist_location, FIRST_NAMES), name_width)), key=len, default=[])
        k, entries = max((_frames(data, at, size, len(names)) for at in
                          _copies(data, size, (head.index_location, HEADER), entry_width)),
                         key=lambda kept: (kept[0], len(kept[1])), default=(0, np.zeros(0, dtype=ENTRY)))
    slots = max(len(entries), k) + 1
    index = np.zeros(slots, dtype=ENTRY)
    index[:len(entries)] = entries
    name_bytes = b"".join(n.encode("utf-8") + b"\0" for n in names)
    name_bytes += bytes(-len(name_bytes) % 64 or 64)
    header = pygsd.gsd_header_struct.pack(*head._replace(
        index_location=size, index_allocated_entries=slots, namelist_location=size + index.nbytes,
        namelist_allocated_entries=len(name_bytes) // 64))
    return pygsd.GSDFile(_View(path, header, size, index.tobytes() + name_bytes))


def open_file(path):
    """``(reader, problem)`` for the GSD file ``path``: gsd.fl's reader and None when the file is
    whole; else :func:`open_intact`'s reader (None if nothing is readable) and what is wrong."""
    import gsd.fl
    try:
        file = gsd.fl.open(name=os.fspath(path), mode="r")
        file.find_matching_chunk_names("")   # decodes every chunk name once: a damaged index fails here
        if whole(path):
            return file, None
        file.close()
        problem = "some of its chunks lie past its end"
    except (RuntimeError, OSError, UnicodeDecodeError) as exc:
        problem = str(exc)
    return open_intact(path), problem


def copy_frames(source, n_frames, out):
    """Write frames ``0 .. n_frames - 1`` of the open GSD file ``source`` (``gsd.fl`` or
    ``gsd.pygsd``) to a new GSD file ``out``, chunk for chunk, with gsd.fl."""
    import gsd.fl
    names = source.find_matching_chunk_names("")
    version = source.schema_version
    with gsd.fl.open(name=os.fspath(out), mode="x", application=source.application, schema=source.schema,
                     schema_version=version) as dst:
        for frame in range(n_frames):
            for name in names:
                if source.chunk_exists(frame=frame, name=name):
                    dst.write_chunk(name, source.read_chunk(frame=frame, name=name))
            dst.end_frame()

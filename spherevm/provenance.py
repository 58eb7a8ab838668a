"""Which code produced a result: a fingerprint of the package's own source files."""
from __future__ import annotations

import functools
import hashlib
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=None)
def source_fingerprint() -> str:
    """First 12 hex digits of the SHA-256 of every ``.py``, ``.cu`` and ``.cuh`` file of the
    installed package (relative path and content, in sorted order).

    Two installs with the same fingerprint run the same code, whatever their version string; it is
    stored in sweep manifests and printed by ``spherevm info``.
    """
    h = hashlib.sha256()
    files = sorted(p for p in _PACKAGE.rglob("*") if p.suffix in (".py", ".cu", ".cuh") and p.is_file())
    for path in files:
        h.update(path.relative_to(_PACKAGE).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:12]

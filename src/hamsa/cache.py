"""The one content-hash cache mechanism of hamsa: keys from inputs, records checked against them.

A computation whose inputs are known (a mesh and a potential for an eigenbasis, the settings of a
benchmark pair, the options of an experiment) is stored under :func:`content_key` of those inputs and of
the code that computes it (:func:`code_fingerprint`), written atomically, and read back only when the
stored key matches: an interrupted run never leaves a half-written entry, and a changed input, or a
changed hamsa between two releases, never reuses a stale one.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from hamsa.errors import HamsaError
from hamsa.files import atomic_write, read_bytes


def content_key(*parts) -> str:
    """A SHA-256 hex digest of ``parts``: arrays (by dtype, shape and bytes), ``bytes``, ``str``, or anything
    JSON can encode (with sorted keys)."""
    digest = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            array = np.ascontiguousarray(part)
            digest.update(f"array:{array.dtype.str}:{array.shape}".encode())
            digest.update(array.tobytes())
        elif isinstance(part, bytes):
            digest.update(b"bytes:" + part)
        elif isinstance(part, str):
            digest.update(b"str:" + part.encode())
        else:
            digest.update(b"json:" + json.dumps(part, sort_keys=True).encode())
        digest.update(b"\x00")
    return digest.hexdigest()


def code_fingerprint(package_root=None) -> str:
    """A SHA-256 hex digest of hamsa's source: every ``.py`` file under ``package_root`` (default: the
    installed ``hamsa`` package), by its path relative to the root and its bytes, in sorted order. Part of
    every cache key, so that an edit to the code (not only a new version number) retires what older code
    computed. Read once per process for the installed package.
    """
    return _fingerprint(Path(package_root or Path(__file__).parent).resolve())


@functools.lru_cache(maxsize=4)
def _fingerprint(root: Path) -> str:
    files = sorted(path.relative_to(root).as_posix() for path in root.rglob("*.py"))
    return content_key(*(part for name in files for part in (name, (root / name).read_bytes())))


def load_record(path, key: str, field: str = "key") -> dict | None:
    """The JSON record at ``path`` if it can be read and its ``field`` equals ``key``, else None."""
    try:
        record = json.loads(read_bytes(path))
    except (HamsaError, ValueError):
        return None
    return record if isinstance(record, dict) and record.get(field) == key else None


def save_record(path, record: dict, indent: int | None = None) -> None:
    """Write ``record`` as JSON to ``path`` atomically (a temporary file renamed into place)."""
    with atomic_write(path, "w") as handle:
        json.dump(record, handle, indent=indent)

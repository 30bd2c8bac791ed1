"""The cache on disk: one file per entry, written atomically and checked when read.

Layout: ``ROOT/<kind>/<key>.pkl`` with ``kind`` one of :data:`KINDS`. A file is :data:`MAGIC`, the
32-byte BLAKE2b digest of the payload, then the payload: the pickle of ``{"key": key, "value":
value}``. A writer pickles into a temporary file ``.tmp-*`` in the same folder, flushes it to disk
and renames it over the entry with :func:`os.replace` (atomic on POSIX file systems, NFS and
Lustre included), so a reader sees the old entry, the new one or none, never a partial file; two
writers of the same key both leave a whole entry (the last rename wins). A file that is missing,
truncated, corrupt, from another format or for another key is a miss, with one warning line; the
job then recomputes the value and its write replaces the bad file.

Pickle runs code when loading: the cache folder must be writable only by people you trust
(entries are created with mode 0600).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

MAGIC = b"quadest-cache 1\n"
KINDS = ("data", "estimator")
SUFFIX = ".pkl"
TEMP_PREFIX = ".tmp-"
_DIGEST_SIZE = 32


def _digest(payload: bytes) -> bytes:
    return hashlib.blake2b(payload, digest_size=_DIGEST_SIZE).digest()


def _warn(message: str) -> None:
    print(f"quadest: warning: cache: {message}", file=sys.stderr)


@dataclass(frozen=True)
class CacheStore:
    """Entries of the cache folder ``root``. Nothing is created before the first :meth:`put`."""

    root: Path

    def path(self, kind: str, key: str) -> Path:
        """The file of entry ``key`` of ``kind``."""
        if kind not in KINDS:
            raise ValueError(f"cache kind {kind!r} is not one of {KINDS}")
        return self.root / kind / f"{key}{SUFFIX}"

    def get(self, kind: str, key: str) -> Any | None:
        """The value stored under ``key``, or ``None`` (a miss) if there is no whole, matching entry."""
        path = self.path(kind, key)
        try:
            blob = path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as exc:
            _warn(f"cannot read {path} ({exc}); computing instead")
            return None
        head = len(MAGIC) + _DIGEST_SIZE
        payload = blob[head:]
        if not blob.startswith(MAGIC) or len(blob) < head:
            problem = "is not a quadest cache entry of this format"
        elif _digest(payload) != blob[len(MAGIC) : head]:
            problem = "is truncated or corrupt (checksum mismatch)"
        else:
            try:
                entry = pickle.loads(payload)
            except Exception as exc:  # any unpickling failure is a miss, never a crash
                problem = f"cannot be unpickled ({type(exc).__name__}: {exc})"
            else:
                if isinstance(entry, dict) and entry.get("key") == key:
                    return entry["value"]
                problem = "holds another key"
        _warn(f"{path} {problem}; recomputing it")
        return None

    def put(self, kind: str, key: str, value: Any) -> bool:
        """Store ``value`` under ``key`` atomically; ``False`` (with a warning) if it could not be
        pickled or written, which never stops the job."""
        path = self.path(kind, key)
        try:
            payload = pickle.dumps({"key": key, "value": value}, protocol=pickle.HIGHEST_PROTOCOL)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            _warn(f"{kind} entry not stored, its value cannot be pickled ({type(exc).__name__}: {exc})")
            return False
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=SUFFIX, dir=path.parent)
        except OSError as exc:
            _warn(f"cannot write into {path.parent} ({exc}); {kind} entry not stored")
            return False
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(MAGIC + _digest(payload))
                f.write(payload)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except OSError as exc:
            _warn(f"cannot write {path} ({exc}); entry not stored")
            return False
        finally:
            Path(tmp).unlink(missing_ok=True)  # left only if the rename did not happen
        return True

    def entries(self, kind: str) -> list[Path]:
        """The entry files of ``kind`` (not the temporary files of writers)."""
        return sorted(p for p in (self.root / kind).glob(f"*{SUFFIX}") if not p.name.startswith(TEMP_PREFIX))

    def temporary_files(self) -> list[Path]:
        """Temporary files of writers still writing, or killed while writing."""
        return sorted(p for kind in KINDS for p in (self.root / kind).glob(f"{TEMP_PREFIX}*"))

    def clear(self) -> int:
        """Delete every entry and temporary file (nothing else in ``root``); the number deleted."""
        files = [p for kind in KINDS for p in self.entries(kind)] + self.temporary_files()
        for path in files:
            path.unlink(missing_ok=True)
        for kind in KINDS:
            folder = self.root / kind
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        return len(files)

"""Durable atomic file writes (private): the one way torchcbl puts a whole file in place.

A write through a temporary name renamed over the target (``os.replace``) leaves the target
whole or as it was for any process that reads it, a killed writer included. It does not, alone,
survive a power cut or a kernel crash: the file system may make the rename durable before the
temporary file's content (the renamed file then reads back empty or cut short), and the rename
itself lives in the directory, which is written back later still. So :func:`write_durably`
flushes the content to the disk (``fsync``) before the rename and the directory after it; when
it returns, the new file is on the disk under its name.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

# What an OS or file system answers when it cannot fsync a directory (some network and FUSE
# file systems, Windows): the rename is then as durable as that file system makes it.
_REFUSED = {errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EACCES, errno.EPERM, errno.EBADF}


def fsync_directory(directory: Path) -> None:
    """Flush ``directory``'s entries (a rename or a new file in it) to the disk.

    Best-effort where the OS or file system refuses to open or fsync a directory.

    Raises:
        OSError: the fsync failed for another reason (e.g. EIO: the disk).
    """
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError as exc:
        if exc.errno in _REFUSED:
            return
        raise
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in _REFUSED:
            raise
    finally:
        os.close(fd)


def write_durably(path: Path, data: bytes, tmp: Path) -> None:
    """Put ``data`` in ``path`` whole, durably: write it to ``tmp`` (same directory), fsync
    it, rename it over ``path`` and fsync the directory.

    A failure (an OSError, or anything raised meanwhile, a KeyboardInterrupt say) is raised
    with ``tmp`` removed; ``path`` is then unchanged, except where only the directory's fsync
    failed (the rename was made).
    """
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        raise
    fsync_directory(path.parent)

"""Writing files so that readers see the old file or the new one, never half.

The lowest layer of endocal's outputs (run folders, model files, planes, force models,
reports): it depends on the standard library only, so every package may use it without
reaching into another (a model file is not a run).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0o022)  # read by setting; restored at once (at import, before any thread writes)
    os.umask(mask)
    return mask


_UMASK = _umask()


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the new one, never half.

    Missing folders on the way are created, as for every output of endocal (a run folder, a
    model, a report): a user names where the file goes, not how to prepare the way.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file private (0600); a run or a model is for the whole lab to read,
        # so it gets the mode any file created here would get (0644 under the usual umask 022)
        os.fchmod(fd, 0o666 & ~_UMASK)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise

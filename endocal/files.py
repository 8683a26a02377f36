"""Writing files so that readers see the old file or the new one, never half; reading endocal's
JSON files (models, planes, force models) with one answer for what can go wrong in them.

The lowest layer of endocal's inputs and outputs (run folders, model files, planes, force
models, reports): it depends on the standard library only, so every package may use it without
reaching into another (a model file is not a run). A file changed by hand, half copied or
written by another program must stop a command in one line naming the file and what is wrong
in it, never inside ``json`` or numpy: the error class is the caller's.
"""

from __future__ import annotations

import json
import math
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


def read_text_document(path: str | Path, what: str, error: type[Exception]) -> str:
    """The UTF-8 text of the file ``path`` (``what`` names it in messages: "model file", "hardware config").

    Raises
    ------
    error
        The file is missing, unreadable, or not UTF-8 text.
    """
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{what} {p} does not exist") from None
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{p}: not a text file (byte {exc.start} is no UTF-8); is it an endocal {what}?") from None


def read_json_document(path: str | Path, what: str, error: type[Exception]):
    """The parsed content of the JSON file ``path`` (``what`` names it in messages: "model file").

    Raises
    ------
    error
        The file is missing, unreadable, not UTF-8 text, or not JSON.
    """
    p = Path(path)
    text = read_text_document(p, what, error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise error(f"{p}: not valid JSON (nested too deeply)") from None


def first_non_finite(node, path: str = "") -> str | None:
    """The path (``parameters/pi_w3/value``) of the first NaN or infinity in a parsed document, or None.

    endocal writes undefined numbers as ``null``, so a NaN or infinity in one of its files
    was put there by something else.
    """
    if isinstance(node, float) and not math.isfinite(node):
        return path.lstrip("/") or "/"
    if isinstance(node, dict):
        items = node.items()
    elif isinstance(node, list):
        items = enumerate(node)
    else:
        return None
    for k, v in items:
        hit = first_non_finite(v, f"{path}/{k}")
        if hit:
            return hit
    return None


def refuse_non_finite(doc, where: str, error: type[Exception]) -> None:
    """Raise ``error`` naming the first NaN or infinity in ``doc``."""
    bad = first_non_finite(doc)
    if bad:
        raise error(f"{where}: field {bad} holds NaN or infinity (endocal writes undefined numbers as null); "
                    "restore the file or make it again")

"""Reading endocal's JSON files (models, planes, force models): one place for what can go wrong.

A file changed by hand, half copied or written by another program must stop the command
in one line naming the file and what is wrong in it, never inside ``json`` or numpy.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from endocal.errors import EndocalError


def read_json_document(path: str | Path, what: str, error: type[EndocalError]):
    """The parsed content of the JSON file ``path`` (``what`` names it in messages: "model file").

    Raises
    ------
    error
        The file is missing, unreadable, not UTF-8 text, or not JSON.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{what} {p} does not exist") from None
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{p}: not a text file (byte {exc.start} is no UTF-8); is it an endocal {what}?") from None
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


def refuse_non_finite(doc, where: str, error: type[EndocalError]) -> None:
    """Raise ``error`` naming the first NaN or infinity in ``doc``."""
    bad = first_non_finite(doc)
    if bad:
        raise error(f"{where}: field {bad} holds NaN or infinity (endocal writes undefined numbers as null); "
                    "restore the file or make it again")

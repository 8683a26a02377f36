"""Versioned ``planes.json``: save and load a :class:`~endocal.planes.calibration.PlanesCalibration`.

File layout::

    {"format": "endocal-planes", "version": 1, "deviation_deg": {...}, "residual_deviation_deg": {...},
     "delta_deg": ..., ...}

i.e. the header plus :meth:`PlanesCalibration.to_json`. Later commands take it with
``--planes planes.json`` and call :meth:`PlanesCalibration.compensate`.
"""

from __future__ import annotations

import json
from pathlib import Path

from endocal.errors import ModelError, OutputExistsError, OutputPathError
from endocal.files import atomic_write_bytes
from endocal.planes.calibration import PlanesCalibration
from endocal.planes.halfplanes import CalibrationError

FORMAT = "endocal-planes"
VERSION = 1


def planes_to_dict(calibration: PlanesCalibration) -> dict:
    """The JSON object written to ``planes.json``: header plus ``calibration.to_json()``."""
    return {"format": FORMAT, "version": VERSION, **calibration.to_json()}


def planes_from_dict(data: dict, where: str = "planes") -> PlanesCalibration:
    """Rebuild a calibration from a ``planes.json`` object.

    Raises
    ------
    ModelError
        Not an endocal planes file, an unsupported version, or malformed content.
    """
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise ModelError(f"{where}: not an endocal planes file (format {found!r}, expected {FORMAT!r})")
    if data.get("version") != VERSION:
        raise ModelError(f"{where}: planes file version {data.get('version')!r} is not supported (this endocal reads version {VERSION})")
    body = {k: v for k, v in data.items() if k not in ("format", "version")}
    try:
        return PlanesCalibration.from_json(body)
    except CalibrationError as exc:
        raise ModelError(f"{where}: {exc}") from None


def save_planes(calibration: PlanesCalibration, path: str | Path, *, force: bool = False) -> Path:
    """Write ``planes.json`` atomically.

    Parameters
    ----------
    calibration : PlanesCalibration
    path : str or Path
    force : bool
        Overwrite an existing file.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``force`` is False.
    OutputPathError
        The file cannot be written.
    """
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError(f"{path} exists; pass force (--force) to overwrite it")
    text = json.dumps(planes_to_dict(calibration), indent=2, allow_nan=False) + "\n"
    try:
        atomic_write_bytes(path, text.encode())
    except OSError as exc:
        raise OutputPathError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def load_planes(path: str | Path) -> PlanesCalibration:
    """Read a ``planes.json`` written by :func:`save_planes`.

    Raises
    ------
    ModelError
        Missing, unreadable, not JSON, wrong format or version, or malformed content.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ModelError(f"planes file {path} does not exist") from None
    except OSError as exc:
        raise ModelError(f"cannot read planes file {path}: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise ModelError(f"planes file {path} is not valid JSON: {exc}") from None
    return planes_from_dict(data, where=str(path))

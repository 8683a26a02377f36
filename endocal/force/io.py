"""Force-model files: versioned, human-readable JSON (never pickle).

Layout (``format: endocal-force-model``, ``version: 1``)::

    {"format": "endocal-force-model", "version": 1, "probe": "tee", "axis": "ap",
     "parameters": {"side": 1, "g": {"value": 2.87, "stderr": 0.008}, ...tables...},
     "heldout": [{"source": ..., "load_n": 0.5, "pred_mean_n": ..., ...}],
     "provenance": {"software": ..., "created_utc": ..., "command": ..., "data": [...]}}
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from endocal.errors import ModelError, OutputExistsError, OutputPathError
from endocal.files import atomic_write_bytes
from endocal.force.model import ForceModel

FORMAT = "endocal-force-model"
VERSION = 1


def force_model_to_dict(model: ForceModel, provenance: dict | None = None) -> dict:
    """Plain JSON-ready dict of a fitted force model."""
    p = {
        "side": model.side,
        "torque_constant_nm_per_a": model.torque_constant_nm_per_a,
        "bending_length_mm": model.bending_length_mm,
        "g": {"value": model.g_, "stderr": model.g_se_, "theta_ref_deg": model.g_theta_ref_deg},
        "g_slope_per_deg": {"value": model.g_slope_per_deg_, "stderr": model.g_slope_se_},
        "compliance_rad_per_nmm": {"value": model.compliance_rad_per_nmm_, "stderr": model.compliance_se_},
        "theta0_deg": model.theta0_deg,
        "bin_deg": model.bin_deg,
        "theta_min_deg": model.theta_min_deg,
        "m_r_loading_nmm": [float(v) for v in model.m_r_loading_nmm],
        "m_r_unloading_nmm": [float(v) for v in model.m_r_unloading_nmm],
        "bend0_rad": [float(v) for v in model.bend0_rad],
        "loads_n": list(model.loads_n),
    }
    return {"format": FORMAT, "version": VERSION, "probe": model.probe, "axis": model.axis, "parameters": p,
            "heldout": [h.to_dict() for h in model.heldout_], "provenance": provenance or {}}


def force_model_from_dict(d: dict, where: str = "force model") -> ForceModel:
    """Rebuild a :class:`ForceModel` from :func:`force_model_to_dict` output.

    Raises
    ------
    ModelError
        Wrong format or version, or a missing or malformed field.
    """
    from endocal.force.model import HeldOut

    if not isinstance(d, dict) or d.get("format") != FORMAT:
        found = d.get("format") if isinstance(d, dict) else None
        raise ModelError(f"{where}: not an endocal force model (format {found!r}, expected {FORMAT!r}); "
                         "write one with `endocal fit force`")
    if d.get("version") != VERSION:
        raise ModelError(f"{where}: force-model version {d.get('version')!r}; this endocal reads version {VERSION}")
    try:
        p = d["parameters"]
        tables = [np.asarray(p[k], float) for k in ("m_r_loading_nmm", "m_r_unloading_nmm", "bend0_rad")]
        if len({t.size for t in tables}) != 1 or tables[0].size < 2:
            raise ValueError("tables of different lengths")
        return ForceModel(
            probe=str(d["probe"]), axis=str(d["axis"]), side=int(p["side"]),
            torque_constant_nm_per_a=float(p["torque_constant_nm_per_a"]),
            bending_length_mm=float(p["bending_length_mm"]), theta0_deg=float(p["theta0_deg"]),
            bin_deg=float(p["bin_deg"]), m_r_loading_nmm=tables[0], m_r_unloading_nmm=tables[1], bend0_rad=tables[2],
            g_=float(p["g"]["value"]), g_se_=float(p["g"]["stderr"]), g_theta_ref_deg=float(p["g"]["theta_ref_deg"]),
            g_slope_per_deg_=float(p["g_slope_per_deg"]["value"]), g_slope_se_=float(p["g_slope_per_deg"]["stderr"]),
            compliance_rad_per_nmm_=float(p["compliance_rad_per_nmm"]["value"]),
            compliance_se_=float(p["compliance_rad_per_nmm"]["stderr"]),
            heldout_=[HeldOut(h["source"], h["load_n"], h["pred_mean_n"], h["rms_error_n"], h["n_samples"])
                      for h in d.get("heldout", [])],
            loads_n=list(p.get("loads_n", [])), theta_min_deg=float(p.get("theta_min_deg", 0.0)), source=where,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{where}: malformed force model ({type(exc).__name__}: {exc})") from None


def save_force_model(model: ForceModel, path: str | Path, *, provenance: dict | None = None, force: bool = False) -> Path:
    """Write ``model`` as versioned JSON.

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``force`` is False.
    OutputPathError
        The file cannot be written.
    """
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError(f"{path} already exists: choose another --out or pass --force")
    text = json.dumps(force_model_to_dict(model, provenance), indent=1)
    try:
        atomic_write_bytes(path, (text + "\n").encode())
    except OSError as exc:
        raise OutputPathError(f"cannot write {path}: {exc.strerror}") from None
    return path


def load_force_model(path: str | Path) -> ForceModel:
    """Read a force-model file written by :func:`save_force_model`.

    Raises
    ------
    ModelError
        Missing file, not JSON, or not a valid force model.
    """
    path = Path(path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelError(f"force model {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelError(f"force model {path} cannot be read as JSON: {exc}") from None
    return force_model_from_dict(d, where=str(path))

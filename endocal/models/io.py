"""Model files: versioned, human-readable JSON (never pickle).

Layout (``format: endocal-model``, ``version: 2``)::

    {"format": "endocal-model", "version": 2,
     "axis": "ml", "base": "pi", "settings": {...}, "out_of_range": "error", "fixed": null,
     "effects": [{"name": "envelope", "settings": {}}],
     "structure": {...resolved settings, thresholds, knots...},
     "parameters": {"pi_r": {"value": 0.1183, "stderr": 0.002, "fixed": false}, ...},
     "cmd_range_deg": [-60.0, 60.0],
     "correlation": {"names": [...], "matrix": [[...]]},
     "fit": {...FitReport...}, "training_data": [{"sha256": "...", "n_samples": 1400}]}

Floats are written with Python's shortest round-trip repr, so a loaded model
predicts exactly what the saved one did. Infinite or undefined numbers are ``null``.

Version 2 changed one thing: a ``bspline`` branch is its first coefficient and
non-negative increments (``bspline_up_c0``, ``bspline_up_dc1``, ...) instead of its
coefficients (``bspline_up_c0``, ``bspline_up_c1``, ...). Version-1 files still load:
:func:`upgrade_v1` rewrites them (values, standard errors and correlations alike).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from endocal.errors import ModelError, OutputPathError
from endocal.files import atomic_write_bytes
from endocal.models.base import FitReport, HysteresisModel
from endocal.models.effects import EFFECTS
from endocal.models.registry import BASES

FORMAT = "endocal-model"
VERSION = 2
#: Optional top-level fields: who made the file, from what (endocal version, data files and hashes, command).
_OPTIONAL = {"provenance"}
_KEYS = {"format", "version", "axis", "base", "settings", "out_of_range", "fixed", "effects", "structure",
         "parameters", "cmd_range_deg", "correlation", "fit", "training_data"}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _from_num(x, default: float) -> float:
    return default if x is None else float(x)


def model_to_dict(model: HysteresisModel) -> dict:
    """A fitted model as a JSON-able dict (see the module docstring for the layout)."""
    model._require_fitted()
    fixed = getattr(model, "fixed_", {})
    corr = model.correlation_
    return {
        "format": FORMAT,
        "version": VERSION,
        "axis": model.axis,
        "base": model.base_name,
        "settings": model.get_settings(),
        "out_of_range": model.out_of_range,
        "fixed": None if model.fixed is None else {k: float(v) for k, v in model.fixed.items()},
        "effects": [{"name": e.name, "settings": e.settings()} for e in model.effects_],
        "structure": model.structure_,
        "parameters": {n: {"value": float(v), "stderr": _num(model.stderr_[n]), "fixed": n in fixed}
                       for n, v in model.params_.items()},
        "cmd_range_deg": [_num(x) for x in model.cmd_range_deg_],
        "correlation": {"names": list(model.param_names_),
                        "matrix": [[_num(x) for x in row] for row in np.asarray(corr)]},
        "fit": None if model.fit_report_ is None else model.fit_report_.to_dict(),
        "training_data": list(model.training_data_),
    }


def model_from_dict(d: dict, where: str = "model") -> HysteresisModel:
    """Rebuild a fitted model from :func:`model_to_dict` output.

    Raises
    ------
    ModelError
        Not an endocal model, unknown version, unknown or missing fields, unknown base
        or effect, parameters that do not match the model.
    """
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise ModelError(f"{where}: not an endocal model file (expected \"format\": \"{FORMAT}\")")
    if d.get("version") == 1:
        d = upgrade_v1(d, where)
    if d.get("version") != VERSION:
        raise ModelError(f"{where}: unknown model file version {d.get('version')!r}; this endocal reads versions 1 to "
                         f"{VERSION} (upgrade endocal or refit the model)")
    unknown = set(d) - _KEYS - _OPTIONAL
    missing = _KEYS - set(d)
    if unknown or missing:
        raise ModelError(f"{where}: wrong fields for a version-{VERSION} model file (unknown {sorted(unknown)}, "
                         f"missing {sorted(missing)})")
    base = d["base"]
    if base not in BASES:
        raise ModelError(f"{where}: unknown base model '{base}' (known: {', '.join(BASES)})")
    try:
        effects = []
        for e in d["effects"]:
            if e["name"] not in EFFECTS:
                raise ModelError(f"{where}: unknown effect '{e['name']}' (known: {', '.join(sorted(EFFECTS))})")
            effects.append(EFFECTS[e["name"]](**e["settings"]))
        model = BASES[base](**d["settings"], effects=effects, fixed=d["fixed"], axis=d["axis"],
                            out_of_range=d["out_of_range"])
        model._check_common()
        effects = model._ordered(model._effects())
        structure = dict(d["structure"])
        owners = model._owners(effects, structure)
        params = d["parameters"]
        if set(params) != set(owners):
            raise ModelError(f"{where}: parameters {sorted(params)} do not match the model's {sorted(owners)}")
        model._owner_map_ = owners
        model.effects_ = effects
        model.structure_ = structure
        model.params_ = {n: float(params[n]["value"]) for n in owners}
        model.stderr_ = {n: _from_num(params[n]["stderr"], math.inf) for n in owners}
        model.fixed_ = {n: model.params_[n] for n in owners if params[n]["fixed"]}
        lo, hi = d["cmd_range_deg"]
        model.cmd_range_deg_ = (_from_num(lo, -math.inf), _from_num(hi, math.inf))
        names = list(d["correlation"]["names"])
        model.param_names_ = names
        corr = np.array([[_from_num(x, math.nan) for x in row] for row in d["correlation"]["matrix"]], dtype=float)
        model.correlation_ = corr.reshape(len(names), len(names))
        se = np.array([model.stderr_[n] for n in names])
        model.covariance_ = model.correlation_ * np.outer(se, se)
        model.fit_report_ = None if d["fit"] is None else FitReport(**d["fit"])
        model.training_data_ = list(d["training_data"])
        model.provenance_ = dict(d.get("provenance") or {})
    except ModelError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{where}: malformed model file ({type(exc).__name__}: {exc})") from None
    return model


def upgrade_v1(d: dict, where: str = "model") -> dict:
    """A version-1 model dict as version 2: B-spline coefficients become first value and increments.

    ``Δc_i = c_i - c_(i-1)`` is linear in the coefficients, so the covariance maps exactly
    (``A Σ Aᵀ``) and the standard errors and correlations are rewritten from it. Other
    bases are unchanged. A version-1 B-spline may have a falling stretch (negative
    increments): it predicts as before, a refit makes it monotone.
    """
    d = {**d, "version": 2}
    if d.get("base") != "bspline":
        return d
    try:
        params = dict(d["parameters"])
        renames = {}
        for branch in ("up", "down"):
            i = 1
            while f"bspline_{branch}_c{i}" in params:
                renames[f"bspline_{branch}_c{i}"] = (f"bspline_{branch}_dc{i}", f"bspline_{branch}_c{i - 1}")
                i += 1
        if set(renames) & set(d.get("fixed") or {}):
            raise ModelError(f"{where}: a version-1 B-spline with fixed coefficients cannot be converted; refit it")
        names = list(d["correlation"]["names"])
        se = np.array([_from_num(params[n]["stderr"], math.nan) for n in names])
        corr = np.array([[_from_num(x, math.nan) for x in row] for row in d["correlation"]["matrix"]], dtype=float)
        cov = corr.reshape(len(names), len(names)) * np.outer(se, se)
        col = {n: i for i, n in enumerate(names)}
        A = np.eye(len(names))
        for old, (_, prev) in renames.items():
            if old in col and prev in col:
                A[col[old], col[prev]] = -1.0
        cov = A @ cov @ A.T
        new_se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            new_corr = cov / np.outer(new_se, new_se)
        out = {}
        for n, entry in params.items():
            if n in renames:
                new, prev = renames[n]
                stderr = float(new_se[col[n]]) if n in col else entry["stderr"]
                out[new] = {**entry, "value": float(entry["value"]) - float(params[prev]["value"]), "stderr": _num(stderr)}
            else:
                out[n] = entry
        d["parameters"] = out
        d["correlation"] = {"names": [renames.get(n, (n,))[0] for n in names],
                            "matrix": [[_num(x) for x in row] for row in new_corr]}
    except ModelError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{where}: malformed version-1 model file ({type(exc).__name__}: {exc})") from None
    return d


def save_model(model: HysteresisModel, path, provenance: dict | None = None) -> None:
    """Write ``model`` to ``path`` as indented JSON.

    ``provenance`` (endocal version, data files and their SHA-256, command, time) is stored
    under ``"provenance"`` and comes back as ``model.provenance_``.

    Raises
    ------
    OutputPathError
        The file cannot be written.
    """
    d = model_to_dict(model)
    prov = provenance if provenance is not None else getattr(model, "provenance_", None)
    if prov:
        d["provenance"] = prov
    text = json.dumps(d, indent=2, allow_nan=False)
    try:
        atomic_write_bytes(Path(path), (text + "\n").encode())
    except OSError as exc:
        raise OutputPathError(f"cannot write model file {path}: {exc.strerror or exc}") from None


def load_model(path) -> HysteresisModel:
    """Read a model file written by :func:`save_model`.

    Raises
    ------
    ModelError
        Missing or unreadable file, invalid JSON, wrong format, version or fields.
    """
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise ModelError(f"model file {p} does not exist") from None
    except OSError as exc:
        raise ModelError(f"cannot read model file {p}: {exc.strerror or exc}") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelError(f"{p}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return model_from_dict(d, where=str(p))

"""Model files: versioned, human-readable JSON (never pickle).

Layout (``format: endocal-model``, ``version: 2``)::

    {"format": "endocal-model", "version": 2,
     "axis": "ml", "base": "pi", "settings": {...}, "out_of_range": "error", "fixed": null,
     "effects": [{"name": "envelope", "settings": {}}],
     "structure": {...resolved settings, thresholds, knots...},
     "parameters": {"pi_r": {"value": 0.1183, "stderr": 0.002, "fixed": false}, ...},
     "cmd_range_deg": [-60.0, 60.0], "drive_unit": "deg",
     "correlation": {"names": [...], "matrix": [[...]]},
     "fit": {...FitReport...}, "training_data": [{"sha256": "...", "n_samples": 1400}]}

A user's effect (``--effects-file``, :mod:`endocal.models.userfile`) carries its source in its
entry, ``{"name": "wear", "settings": {}, "source": {"path": ..., "module": ..., "sha256": ...}}``,
and a user's base in ``base_source``; loading the model without that file, or with the file
changed and not given again, is refused (:func:`~endocal.models.userfile.check_model_sources`).

``drive_unit`` is the unit of the command the model was fitted on: ``deg`` for a knob, ``mm``
for a linear stage pulling the tendon. The parameters keep their names in either unit
(``deadzone_slack_deg``, ``cmd_range_deg``), and hold the drive's unit: a model of a linear drive
prints them as ``slack_mm`` (:func:`~endocal.models.base.in_drive_unit`). A file without the
field (written before linear drives were read) is a knob's, in deg.

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

from endocal.errors import CompensationRefusedError, ModelError, OutputPathError
from endocal.files import atomic_write_bytes, read_json_document, refuse_non_finite
from endocal.models.base import FitReport, HysteresisModel
from endocal.models.effects import EFFECTS
from endocal.models.registry import BASES

FORMAT = "endocal-model"
VERSION = 2
#: Optional top-level fields: who made the file, from what (endocal version, data files and hashes, command);
#: the drive's unit (deg when absent).
_OPTIONAL = {"provenance", "drive_unit", "base_source"}
#: Units a model's command may be in (endocal.runs.aligned.DRIVE_UNITS).
_DRIVE_UNITS = ("deg", "mm")
_KEYS = {"format", "version", "axis", "base", "settings", "out_of_range", "fixed", "effects", "structure",
         "parameters", "cmd_range_deg", "correlation", "fit", "training_data"}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _from_num(x, default: float) -> float:
    return default if x is None else float(x)


def model_to_dict(model: HysteresisModel) -> dict:
    """A fitted model as a JSON-able dict (see the module docstring for the layout)."""
    from endocal.models.userfile import sources_of_model

    model._require_fitted()
    fixed = getattr(model, "fixed_", {})
    corr = model.correlation_
    sources, base_source = sources_of_model(model)
    d = {
        "format": FORMAT,
        "version": VERSION,
        "axis": model.axis,
        "base": model.base_name,
        "settings": model.get_settings(),
        "out_of_range": model.out_of_range,
        "fixed": None if model.fixed is None else {k: float(v) for k, v in model.fixed.items()},
        "effects": [{"name": e.name, "settings": e.settings(), **({"source": s.to_dict()} if s else {})}
                    for e, s in zip(model.effects_, sources)],
        "structure": model.structure_,
        "parameters": {n: {"value": float(v), "stderr": _num(model.stderr_[n]), "fixed": n in fixed}
                       for n, v in model.params_.items()},
        "cmd_range_deg": [_num(x) for x in model.cmd_range_deg_],
        "drive_unit": model.drive_unit_,
        "correlation": {"names": list(model.param_names_),
                        "matrix": [[_num(x) for x in row] for row in np.asarray(corr)]},
        "fit": None if model.fit_report_ is None else model.fit_report_.to_dict(),
        "training_data": list(model.training_data_),
    }
    if base_source is not None:
        d["base_source"] = base_source.to_dict()
    return d


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
    _check_shape(d, where)
    from endocal.models.userfile import check_model_sources

    check_model_sources(d, where)  # a user's effect or base: registered from the file the model was fitted with
    base = d["base"]
    if not isinstance(base, str) or base not in BASES:
        raise ModelError(f"{where}: unknown base model '{base}' (known: {', '.join(BASES)})")
    try:
        effects = []
        for e in d["effects"]:
            if e["name"] not in EFFECTS:
                raise ModelError(f"{where}: unknown effect '{e['name']}' (known: {', '.join(sorted(EFFECTS))})")
            try:
                effects.append(EFFECTS[e["name"]].from_settings(e["settings"]))
            except ModelError as exc:  # an effect's own refusal, which names it (an unknown form, a load's column)
                raise ModelError(f"{where}: {exc}") from None
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
        model.drive_unit_ = d.get("drive_unit", "deg")
        if model.drive_unit_ not in _DRIVE_UNITS:
            raise ModelError(f"{where}: unknown drive_unit {model.drive_unit_!r}; a model's command is in "
                             f"{' or '.join(_DRIVE_UNITS)}")
        names = list(d["correlation"]["names"])
        model.param_names_ = names
        corr = np.array([[_from_num(x, math.nan) for x in row] for row in d["correlation"]["matrix"]], dtype=float)
        model.correlation_ = corr.reshape(len(names), len(names))
        se = np.array([model.stderr_[n] for n in names])
        with np.errstate(over="ignore", invalid="ignore"):  # an error of 1e200 is an infinite one, as written
            model.covariance_ = model.correlation_ * np.outer(se, se)
        model.fit_report_ = None if d["fit"] is None else FitReport.from_dict(d["fit"])
        model.training_data_ = list(d["training_data"])
        model.provenance_ = dict(d.get("provenance") or {})
        _check_works(model, where)
    except ModelError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise ModelError(f"{where}: malformed model file ({type(exc).__name__}: {_first_line(exc)})") from None
    return model


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _check_shape(d: dict, where: str) -> None:
    """Types of a model file's fields, before anything is built from them.

    A file changed by hand or half copied must stop here, on one line naming the field,
    not later inside numpy or matplotlib. :func:`save_model` writes every undefined or
    infinite number as ``null``, so a NaN or an infinity in a file was not written by it.

    Raises
    ------
    ModelError
    """
    refuse_non_finite(d, where, ModelError)

    def need(ok: bool, field: str, what: str) -> None:
        if not ok:
            raise ModelError(f"{where}: field {field} must be {what}; restore the file or refit the model")

    for key in ("settings", "structure"):
        need(isinstance(d[key], dict), key, "an object")
    need(d["axis"] is None or (isinstance(d["axis"], str) and d["axis"].isidentifier()), "axis",
         "the name of a bending axis (or null)")
    need(isinstance(d["out_of_range"], str), "out_of_range", "a text")
    need(isinstance(d["effects"], list) and all(isinstance(e, dict) and isinstance(e.get("name"), str)
                                                 and isinstance(e.get("settings"), dict) for e in d["effects"]),
         "effects", 'a list of {"name": ..., "settings": {...}}')
    need(d["fixed"] is None or (isinstance(d["fixed"], dict) and all(_is_number(v) for v in d["fixed"].values())),
         "fixed", "null or an object of numbers")
    need(isinstance(d["parameters"], dict), "parameters", "an object")
    for name, entry in d["parameters"].items():
        need(isinstance(entry, dict) and set(entry) == {"value", "stderr", "fixed"}, f"parameters/{name}",
             'an object {"value", "stderr", "fixed"}')
        need(_is_number(entry["value"]), f"parameters/{name}/value", "a number")
        need(entry["stderr"] is None or (_is_number(entry["stderr"]) and entry["stderr"] >= 0),
             f"parameters/{name}/stderr", "a number >= 0 or null")
        need(isinstance(entry["fixed"], bool), f"parameters/{name}/fixed", "true or false")
    rng = d["cmd_range_deg"]
    need(isinstance(rng, list) and len(rng) == 2 and all(x is None or _is_number(x) for x in rng)
         and (None in rng or rng[0] < rng[1]), "cmd_range_deg", "[low, high] with low < high (null: unbounded)")
    corr = d["correlation"]
    need(isinstance(corr, dict) and isinstance(corr.get("names"), list) and isinstance(corr.get("matrix"), list),
         "correlation", 'an object {"names": [...], "matrix": [[...]]}')
    n = len(corr["names"])
    need(all(isinstance(s, str) for s in corr["names"]), "correlation/names", "a list of parameter names")
    need(len(corr["matrix"]) == n and all(isinstance(r, list) and len(r) == n
                                          and all(x is None or _is_number(x) for x in r) for r in corr["matrix"]),
         "correlation/matrix", f"{n} rows of {n} numbers (null: undefined)")
    # the structure's counts (operators, knots) index parameters: a count out of all proportion with
    # the file's parameters is a damaged file, refused before it sizes any array
    limit = 10 * len(d["parameters"]) + 100
    for key, value in d["structure"].items():
        need(not (isinstance(value, int) and not isinstance(value, bool) and abs(value) > limit),
             f"structure/{key}", f"a count in proportion with the file's {len(d['parameters'])} parameters")
    need(d["fit"] is None or isinstance(d["fit"], dict), "fit", "null or an object")
    if isinstance(d["fit"], dict):
        _check_fit_report(d["fit"], need)
    need(isinstance(d["training_data"], list) and all(
        isinstance(t, dict) and isinstance(t.get("sha256"), str) and _is_count(t.get("n_samples"))
        for t in d["training_data"]), "training_data", 'a list of {"sha256": "...", "n_samples": N}')
    _check_provenance(d.get("provenance"), need)


#: FitReport's fields and the JSON types each must have (what the fit summary, `validate` and the
#: report format: a text where a number is printed with :.3f stops them, not the loader).
_FIT_FIELDS = {"success": "bool", "status": "int", "message": "str", "nfev": "count", "njev": "count",
               "cost": "number", "rmse_deg": "number", "n_samples": "count", "n_runs": "count", "n_free": "count",
               "rank_deficient": "bool", "method": "str", "warnings": "texts", "estimated_starts": "objects",
               "warning_keys": "texts"}
_FIT_REQUIRED = set(_FIT_FIELDS) - {"method", "warnings", "estimated_starts", "warning_keys"}


def _is_count(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= 0


def _of_type(x, kind: str) -> bool:
    return {"bool": lambda: isinstance(x, bool),
            "int": lambda: isinstance(x, int) and not isinstance(x, bool),
            "count": lambda: _is_count(x),
            "number": lambda: _is_number(x) and x >= 0,
            "str": lambda: isinstance(x, str),
            "texts": lambda: isinstance(x, list) and all(isinstance(s, str) for s in x),
            "objects": lambda: isinstance(x, list) and all(isinstance(s, dict) for s in x)}[kind]()


def _check_fit_report(fit: dict, need) -> None:
    """The ``fit`` object's fields: each known, present when required, of its type."""
    unknown, missing = set(fit) - set(_FIT_FIELDS), _FIT_REQUIRED - set(fit)
    need(not unknown and not missing, "fit", f"an object with the fields {', '.join(_FIT_FIELDS)} "
         f"(unknown {sorted(unknown)}, missing {sorted(missing)})")
    for key, value in fit.items():
        need(_of_type(value, _FIT_FIELDS[key]), f"fit/{key}",
             {"bool": "true or false", "int": "an integer", "count": "an integer >= 0", "number": "a number >= 0",
              "str": "a text", "texts": "a list of texts", "objects": "a list of objects"}[_FIT_FIELDS[key]])


def _check_provenance(prov, need) -> None:
    """A model file's ``provenance``: null, or an object whose known fields have the types its readers use.

    ``validate`` finds the estimation data and the planes through it and checks the probe of
    the records against it, the report lists it: a field changed by hand must stop here, on a
    line naming it. Fields it does not know are kept (a provenance is a record, not a setting).
    """
    if prov is None:
        return
    need(isinstance(prov, dict), "provenance", "null or an object")

    def text_or_null(key: str) -> None:
        need(prov.get(key) is None or isinstance(prov[key], str), f"provenance/{key}", "a text or null")

    for key in ("created_utc", "command", "cwd", "planes", "planes_sha256"):
        text_or_null(key)
    need(prov.get("software") is None or isinstance(prov["software"], dict), "provenance/software",
         "null or an object")

    def file_ref(x) -> bool:
        return (isinstance(x, dict) and isinstance(x.get("path"), str) and bool(x["path"])
                and (x.get("sha256") is None or isinstance(x["sha256"], str)))

    need(prov.get("data") is None or (isinstance(prov["data"], list) and all(file_ref(x) for x in prov["data"])),
         "provenance/data", 'a list of {"path": "...", "sha256": "..."}')
    need(prov.get("start_from") is None or file_ref(prov["start_from"]), "provenance/start_from",
         'null or {"path": "...", "sha256": "..."}')
    probe = prov.get("probe")
    need(probe is None or isinstance(probe, dict), "provenance/probe", 'null or {"name": ..., "bending_axes": [...]}')
    if probe:
        need(isinstance(probe.get("name"), str) and bool(probe["name"]), "provenance/probe/name",
             "the name of the probe the model was fitted on")
        axes = probe.get("bending_axes", [])
        need(isinstance(axes, list) and all(isinstance(a, str) for a in axes), "provenance/probe/bending_axes",
             "a list of axis names")


class _AnyColumn(dict):
    """Extra columns for a smoke test: any column an effect asks for reads as zeros."""

    def __init__(self, n: int):
        super().__init__()
        self._n = n

    def __missing__(self, key):
        return np.zeros(self._n)


def _check_works(model: HysteresisModel, where: str) -> None:
    """A loaded model predicts and inverts finite angles over its fitted range, or is refused.

    Types alone do not make a working model: a weight of 1e308 overflows, a knot moved by
    hand unsorts the spline. A short sine over the fitted command range (or +-10 deg when
    unbounded) is run forward and back, as every command that reads a model would.

    Raises
    ------
    ModelError
    """
    import warnings

    lo, hi = model.cmd_range_deg_
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = -10.0, 10.0
    t_s = np.arange(200) * 0.02
    cmd = lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * 0.5 * t_s))
    setting, model.out_of_range = model.out_of_range, "clamp"  # a file may hold a model that cannot reach all
    try:                                                         # it predicts (a falling version-1 B-spline)
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            y = np.asarray(model.predict(_smoke_data(cmd, t_s)), dtype=float)
            try:
                back = model.inverse(_smoke_data(y, t_s))
            except CompensationRefusedError:  # it predicts and validates; compensating with it says so in one line
                back = cmd
            ok = bool(np.isfinite(y).all()) and bool(np.isfinite(back).all())
    except ModelError as exc:
        raise ModelError(f"{where}: the model file does not make a working model ({_first_line(exc)}); "
                         "restore the file or refit the model") from None
    except (ArithmeticError, ValueError, TypeError, IndexError, KeyError, np.linalg.LinAlgError) as exc:
        raise ModelError(f"{where}: the model file does not make a working model ({type(exc).__name__}: "
                         f"{_first_line(exc)}); restore the file or refit the model") from None
    finally:
        model.out_of_range = setting
    if not ok:
        raise ModelError(f"{where}: the model's parameters predict non-finite angles over its fitted range "
                         "(a value changed by hand?); restore the file or refit the model")


def _smoke_data(x: np.ndarray, t_s: np.ndarray):
    """A record of ``x`` (deg) at times ``t_s`` whose every extra column reads as zeros."""
    from endocal.models.data import HysteresisData

    data = HysteresisData(cmd_deg=x, t_s=t_s)
    object.__setattr__(data, "extras", _AnyColumn(x.size))  # frozen: set past the checks, which need no columns
    return data


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
    d = read_json_document(path, "model file", ModelError)
    return model_from_dict(d, where=str(path))

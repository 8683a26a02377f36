"""Which data a model was estimated on, and whether ``validate`` can use it: the estimation/validation split.

A model file records the data it was fitted on (paths and SHA-256) and the bending planes it
was fitted through (``fit hysteresis --planes``). ``endocal validate MODEL DATA...`` holds
the model against ``DATA`` (the validation data); to test which effect is missing it refits
each candidate on the *estimation* data and scores it on the validation data, the split
every system-identification tool works with. :func:`plan_estimation` decides where the
estimation data comes from and says why:

- ``--train DATA...`` given: those records;
- else the records the model file names, when every one is found and unchanged (same
  SHA-256); a record that moved or changed is an error that names it and asks for
  ``--train`` (or ``--cv rolling``);
- rolling-origin cross-validation on the validation data alone when the model file
  records no training data, when it was fitted on the very records validated here, or on
  request (``--cv rolling``).

Planes are found the same way: ``--planes`` given, else the file the model records (checked
against its hash when one is recorded).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from endocal.errors import ModelError
from endocal.runs.aligned import AlignedData, load_aligned
from endocal.runs.format import sha256_of
from endocal.runs.probes import check_one_probe

CV_CHOICES = ("auto", "rolling", "split")


@dataclass
class EstimationPlan:
    """Where ``validate`` gets its estimation data and planes from.

    Attributes
    ----------
    train : list of AlignedData or None
        Estimation data (None: rolling-origin cross-validation on the validation data).
    train_paths : list of str
        Their paths as the refit command should name them.
    reason : str
        Why this scheme, in words (printed, and recorded in ``--json``).
    planes : PlanesCalibration or None
        Bending planes the model was fitted through.
    planes_path : str or None
        Their file.

    Estimation data that is also validation data is allowed (the scores are then in-sample,
    and :func:`~endocal.validation.offline.validate_offline` says so in its notes).
    """

    train: list[AlignedData] | None
    train_paths: list[str]
    reason: str
    planes: object | None = None
    planes_path: str | None = None


def _locate(recorded: str, model_path: Path | None, fit_cwd: str | None = None) -> Path | None:
    """A recorded path as given (relative to the working folder), else relative to the folder the
    fit ran in (``fit_cwd``, recorded with it), else relative to the model file's folder."""
    p = Path(recorded)
    if p.exists():
        return p
    if p.is_absolute():
        return None
    for folder in ([Path(fit_cwd)] if fit_cwd else []) + ([model_path.parent] if model_path is not None else []):
        if (folder / p).exists():
            return folder / p
    return None


def recorded_planes(model, model_path: str | Path | None, planes_path: str | Path | None = None, *,
                    moved: str | Path | None = None):
    """The bending planes to read data through for ``model``: ``planes_path`` when given, else
    the planes its file records (looked up as given, where the fit ran, then beside the model
    file; hash checked), else ``moved`` when it is that very file (same SHA-256) moved elsewhere.

    Returns
    -------
    (PlanesCalibration or None, str or None)

    Raises
    ------
    ModelError
        Recorded planes missing or changed since the fit.
    """
    from endocal.planes import load_planes

    model_path = Path(model_path) if model_path is not None else None

    if planes_path is not None:
        return load_planes(planes_path), str(planes_path)
    prov = getattr(model, "provenance_", None) or {}
    recorded = prov.get("planes")
    if not recorded:
        return None, None
    found = _locate(recorded, model_path, prov.get("cwd"))
    if found is None and moved is not None and sha256_of(moved) == prov.get("planes_sha256"):
        found = Path(moved)
    if found is None:
        other = f"; {moved} is another file (SHA-256 differs)" if moved is not None else ""
        raise ModelError(f"the model was fitted through the bending planes {recorded}, which are not found{other}: "
                         "give them with --planes (validating without them would score other angles than the fit did)")
    digest = prov.get("planes_sha256")
    if digest and sha256_of(found) != digest:
        raise ModelError(f"the bending planes {found} have changed since the model was fitted through them "
                         "(SHA-256 differs): give the planes it was fitted with via --planes, or refit the model")
    return load_planes(found), str(found)


def plan_estimation(model, val: Sequence[AlignedData], *, model_path: str | Path | None = None,
                    train_paths: Sequence[str | Path] = (), cv: str = "auto",
                    planes_path: str | Path | None = None) -> EstimationPlan:
    """Decide the estimation data and planes for validating ``model`` on ``val``.

    Parameters
    ----------
    model : HysteresisModel
        A loaded model (its ``provenance_`` names its training data and planes).
    val : sequence of AlignedData
        The validation data.
    model_path : path, optional
        The model file (recorded relative paths are also looked up beside it).
    train_paths : sequence of path
        ``--train``: estimation data given explicitly.
    cv : {"auto", "rolling", "split"}
        ``rolling`` forces rolling-origin cross-validation on ``val``; ``split`` requires
        estimation data; ``auto`` uses it when there is any.
    planes_path : path, optional
        ``--planes``: overrides the planes the model records.

    Returns
    -------
    EstimationPlan

    Raises
    ------
    ModelError
        Unknown ``cv``; ``--train`` with ``--cv rolling``; recorded training data that is
        missing or changed; ``--cv split`` without estimation data; recorded planes missing
        or changed.
    RunFormatError
        A validation run recorded on another probe than the one the model's provenance names
        (:func:`~endocal.runs.probes.check_one_probe`): a model describes one probe's tendons.
    """
    if cv not in CV_CHOICES:
        raise ModelError(f"--cv must be one of {', '.join(CV_CHOICES)}, got {cv!r}")
    check_one_probe(val, expected=(getattr(model, "provenance_", None) or {}).get("probe"), what="validation runs",
                    expected_is="the model was fitted on runs of")
    mpath = Path(model_path) if model_path is not None else None
    planes, ppath = recorded_planes(model, mpath, planes_path)
    val_hashes = {a.sha256 for a in val}
    if cv == "rolling":
        if train_paths:
            raise ModelError("--train and --cv rolling exclude each other: rolling-origin cross-validation uses the "
                             "validation data alone; drop one of them")
        return EstimationPlan(None, [], "rolling-origin cross-validation on request (--cv rolling)", planes, ppath)
    if train_paths:
        train = [load_aligned(p) for p in train_paths]
        return EstimationPlan(train, [str(p) for p in train_paths], "estimation data given with --train", planes,
                              ppath)
    recorded = (getattr(model, "provenance_", None) or {}).get("data") or []
    if not recorded:
        if cv == "split":
            raise ModelError("--cv split needs estimation data, and the model file records none: give it with --train")
        return EstimationPlan(None, [], "the model file records no training data", planes, ppath)
    if all(d.get("sha256") in val_hashes for d in recorded):
        if cv == "split":
            raise ModelError("--cv split: the model was fitted on the very data validated here; give other "
                             "estimation data with --train")
        return EstimationPlan(None, [], "the model was fitted on the data validated here: no separate estimation "
                              "data", planes, ppath)
    train, paths = [], []
    for d in recorded:
        found = _locate(d["path"], mpath, (getattr(model, "provenance_", None) or {}).get("cwd"))
        if found is None:
            raise ModelError(f"the model was fitted on {d['path']}, which is not found: give the estimation data with "
                             "--train (or --cv rolling to cross-validate on the validation data alone)")
        a = load_aligned(found)
        if d.get("sha256") and a.sha256 != d["sha256"]:
            raise ModelError(f"{found} has changed since the model was fitted on it (SHA-256 differs): give the data it "
                             "was fitted on with --train, or refit the model")
        train.append(a)
        paths.append(str(found))
    return EstimationPlan(train, paths, "estimation data: the records the model was fitted on (found and unchanged)",
                          planes, ppath)

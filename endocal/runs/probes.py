"""Which probe recorded a run, and refusing runs of several probes where one model describes one probe.

A run folder's ``run.json`` records the probe it was recorded (or imported) on: its name and
bending axes (:meth:`endocal.probe.ProbeConfig.to_dict`). A hysteresis model describes the
tendons of one probe, so a fit over records of two probes, or a model of one probe held
against a record of another, is refused in one line naming both. A bare aligned table
(``.parquet`` / ``.csv``) records no probe and is never refused here (its axes still are, by
:func:`endocal.validation.data.axis_data`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from endocal.errors import RunFormatError


def probe_of(meta: Mapping) -> dict | None:
    """``{"name", "bending_axes"}`` of the probe a ``run.json`` records, or None (a bare table).

    Parameters
    ----------
    meta : mapping
        ``run.json`` content (:attr:`endocal.runs.aligned.AlignedData.meta`).
    """
    probe = (meta or {}).get("probe")
    if not isinstance(probe, Mapping) or not probe.get("name"):
        return None
    return {"name": str(probe["name"]), "bending_axes": [str(a) for a in probe.get("bending_axes") or []]}


def _words(probe: Mapping) -> str:
    axes = ", ".join(probe.get("bending_axes") or [])
    return f"probe '{probe['name']}'" + (f" (axes {axes})" if axes else "")


def check_one_probe(datas: Sequence, *, expected: Mapping | None = None, what: str = "runs",
                    expected_is: str = "the others") -> dict | None:
    """The one probe ``datas`` were recorded on, refusing records of another.

    Parameters
    ----------
    datas : sequence of AlignedData
        Loaded run folders or aligned tables.
    expected : mapping, optional
        The probe they must match (``{"name", "bending_axes"}``, e.g. what a model's
        provenance records); default: the first record that names one.
    what : str
        What to give instead, in the message (``"validation runs"``).
    expected_is : str
        What ``expected`` belongs to, in the message (``"the model was fitted on runs of"``).

    Returns
    -------
    dict or None
        The probe (``expected`` when given), None when no record names one.

    Raises
    ------
    RunFormatError
        A record of a probe with another name than the others' (or than ``expected``).
    """
    first, first_src = (dict(expected), None) if expected else (None, None)
    for a in datas:
        probe = probe_of(getattr(a, "meta", {}))
        if probe is None:
            continue
        if first is None:
            first, first_src = probe, a.source
            continue
        if probe["name"] != first["name"]:
            theirs = f"{first_src} is a run of {_words(first)}" if first_src is not None else f"{expected_is} {_words(first)}"
            raise RunFormatError(f"{a.source} is a run of {_words(probe)}, but {theirs}: a hysteresis model describes "
                                 f"one probe's tendons; give {what} of probe '{first['name']}' only")
    return first

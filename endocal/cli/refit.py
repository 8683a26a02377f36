"""The refit a suspect suggests, as the ``endocal fit hysteresis`` command a user types.

The library returns what to refit (:class:`~endocal.validation.refit.Refit`); the command
line says how to type it, in the terminal summary and as the ``command`` field of every
suspect in ``validate --json``.
"""

from __future__ import annotations

import json
import shlex
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the command line's help must not load the library (numpy, scipy)
    from endocal.validation.refit import Refit


def refit_command(refit: Refit) -> str:
    """``endocal fit hysteresis DATA... --axis AXIS --model BASE --effects E1,E2 [--planes P] [--set K=V...]
    [--start-from M] --out OUT``.

    Arguments are quoted for a POSIX shell where they need it (a lab folder with a space in its name);
    setting values are written as JSON, as ``--set`` reads them.
    """
    parts = list(refit.data_paths)
    if refit.axis:
        parts += ["--axis", refit.axis]
    parts += ["--model", refit.base]
    if refit.effects:
        parts += ["--effects", ",".join(refit.effects)]
    if refit.planes_path:
        parts += ["--planes", refit.planes_path]
    for k, v in refit.settings.items():
        parts += ["--set", f"{k}={json.dumps(v)}"]
    if refit.start_from:
        parts += ["--start-from", refit.start_from]
    parts += ["--out", refit.out_path]
    return "endocal fit hysteresis " + shlex.join(parts)


def with_refit_commands(d: dict, scan) -> dict:
    """``validate``'s JSON object ``d`` (:meth:`ValidationResult.to_dict`) with a ``command`` after every
    suspect's ``refit``, in ``suspects``, ``scan.suspects`` and ``scan.tested``, rendered from ``scan``
    (the :class:`~endocal.validation.suspects.ScanResult` ``d`` was made from)."""
    scan_d = d.get("scan") or {}
    for dicts, suspects in ((d.get("suspects", []), scan.suspects), (scan_d.get("suspects", []), scan.suspects),
                            (scan_d.get("tested", []), scan.tested)):
        for i, (sd, s) in enumerate(zip(dicts, suspects, strict=True)):
            items = list(sd.items())
            at = [k for k, _ in items].index("refit") + 1
            dicts[i] = dict([*items[:at], ("command", refit_command(s.refit)), *items[at:]])
    for bd, b in zip(scan_d.get("bases", []), getattr(scan, "bases", ()), strict=True):  # the base candidates too
        bd["command"] = refit_command(b.refit)
    return d

"""The check protocol: fixed, built-in, at most 90 s, both knobs, inside the model's fitted range.

The protocol is the shipped ``protocols/check.toml`` (a triangle on each knob in turn), never a
local file of the same name: a probe's checks are comparable only if they are the same motion
every time. The one thing set per probe is the amplitude, from the fitted command range of the
probe's models (the same for every check of one calibration), so the check never asks a model
to predict beyond what it was fitted on.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from endocal.errors import ModelError

#: Largest amplitude of the check (deg of knob): the shipped file's; a wider fitted range keeps it.
MAX_AMPLITUDE_DEG = 45.0
#: Share of the fitted half-range the check may use: the loop's end stays 10 % inside the range.
RANGE_SHARE = 0.9
#: Below this amplitude (deg) a triangle shows no loop worth scoring (dead bands of 5-15 deg).
MIN_AMPLITUDE_DEG = 15.0
#: The protocol's upper bound of rig time (s): issue 34, "a check takes <= 90 s of rig time".
MAX_DURATION_S = 90.0
PROTOCOL_NAME = "check"


def check_amplitude_deg(models: Mapping) -> float:
    """The check's amplitude (deg of knob) inside every model's fitted command range.

    Parameters
    ----------
    models : mapping of axis -> HysteresisModel
        Fitted models (``cmd_range_deg_``).

    Returns
    -------
    float
        ``min(45, 0.9 * min(-lo, hi))`` over the models, rounded down to a whole degree, so one
        calibration's checks are the same motion every time.

    Raises
    ------
    ModelError
        A fitted range that does not reach :data:`MIN_AMPLITUDE_DEG` on both sides of the rest (0).
    """
    amp = MAX_AMPLITUDE_DEG
    for axis, m in models.items():
        lo, hi = m.cmd_range_deg_
        half = min(-lo, hi)
        if not math.isfinite(half):
            continue
        if RANGE_SHARE * half < MIN_AMPLITUDE_DEG:
            raise ModelError(f"the model of axis '{axis}' was fitted on commands {lo:.1f} .. {hi:.1f} deg: the check "
                             f"needs +-{MIN_AMPLITUDE_DEG / RANGE_SHARE:.1f} deg about the rest; refit it on a wider motion")
        amp = min(amp, RANGE_SHARE * half)
    return float(math.floor(amp))


def check_protocol(models: Mapping):
    """The shipped check protocol at the amplitude of ``models``.

    Returns
    -------
    Protocol
        ``protocols/check.toml`` with ``amplitude_deg`` set (:func:`check_amplitude_deg`).
    """
    from endocal.protocols import load_protocol
    from endocal.protocols.protocol import shipped_protocols_dir

    return load_protocol(shipped_protocols_dir() / f"{PROTOCOL_NAME}.toml",
                         overrides={"amplitude_deg": check_amplitude_deg(models)})

"""The keys of the summary's warnings and notes (endocal/messages.py, endocal/cli/messages.py): every key
a message is made with is explained in KEYS, and each library message carries its key from birth (never
found from its words), through a model file too."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from endocal import messages
from endocal.cli._common import slow_clock_warning
from endocal.cli.messages import KEYS, Message, capped, head, key_of, keyed, keyed_lines

PKG = Path(messages.__file__).parent  # endocal/: every module of the package


def test_every_key_a_message_is_made_with_is_explained():
    used = set(messages._SHORT) | set(messages._GROUPED)
    for path in PKG.rglob("*.py"):
        text = path.read_text()
        used |= set(re.findall(r'key="([a-z-]+)"', text))  # keyed(..., key="not-converged")
        used |= set(re.findall(r"(?:note|warning)\[([a-z-]+)\]", text))  # f"note[not-evaluated]: ..."
        used |= set(re.findall(r'"([a-z]+(?:-[a-z]+)*)"\)+(?:\s*for\b|\]|,|$)', text, re.M)) & set(KEYS)
        used |= set(re.findall(r'\("([a-z-]+)", ', text)) & set(KEYS)  # ("gap", text) pairs
    used.discard("a-z-")
    assert used and used <= set(KEYS), sorted(used - set(KEYS))
    # a key unknown to KEYS is refused where the message is made, and where a command prints a pair
    with pytest.raises(KeyError, match="startcut"):
        Message("a record starts mid-swing", "startcut")
    with pytest.raises(KeyError, match="startcut"):
        keyed_lines([("startcut", "a record starts mid-swing")])
    # a meaning a reader can act on: sentences, no key left blank
    assert all(len(v) > 40 and v.endswith(".") for v in KEYS.values()), [k for k, v in KEYS.items() if len(v) <= 40]


def test_the_library_s_warnings_carry_their_keys_and_keep_their_facts():
    from endocal.models.base import _loose_parameters, _no_better_than_a_line
    from endocal.models.data import HysteresisData
    from endocal.validation.data import glitch_note

    owner = object()  # an effect without why_loose: each loose parameter gets its own line
    loose = _loose_parameters(["rate_gain_s", "creep_fraction"], {"rate_gain_s": (owner, "gain_s"),
                                                                   "creep_fraction": (owner, "fraction")},
                              {"rate_gain_s": 0.05, "creep_fraction": 0.09}, {"rate_gain_s": 0.01, "creep_fraction": 0.15},
                              np.array([0.0, 0.0]), np.array([0.05, 0.95]))
    assert [key_of(w) for w in loose] == ["at-bound", "unidentified"]
    assert keyed(loose[0]) == "warning[at-bound]: rate_gain_s = 0.05 sits at its upper bound 0.05"
    cmd = np.tile(np.r_[np.linspace(0, 40, 50), np.linspace(40, 0, 50)], 3)
    line = _no_better_than_a_line(HysteresisData(cmd_deg=cmd, meas_deg=0.7 * cmd), 1.0, "pi")
    assert key_of(line[0]) == "line-fit" and head(line[0]).startswith("the fit (1 deg RMSE) is no better than")
    glitch = glitch_note([("val.csv", 1, 5, 0, 3.0)], "ap")
    assert key_of(glitch) == "glitches" and head(glitch).startswith("left out 5 measured ap angle(s) and 1 ap command(s)")
    slow = slow_clock_warning(100, 1000.0)
    assert keyed(slow) == "warning[slow-clock]: 0.1 samples per second: is t_s in seconds?"
    # a topic first ("load: ..."): the fact after it; several make one line
    untestable = [Message("load: no extra column varies in the estimation data (8 constant): load cannot be identified "
                          "(log a covariate)", "untestable"),
                  Message("coupling: the other knob never moves: coupling cannot be identified (run `circle`)",
                          "untestable")]
    assert keyed(untestable[0], "note") == ("note[untestable]: load: no extra column varies in the estimation data "
                                            "(8 constant)")
    assert keyed_lines(untestable, "note") == ["note[untestable]: load, coupling cannot be tested on this data"]
    # "fact; what to do": the fact
    assert head("candidates fitted on 1 estimation sample in 6 (4335 of 26002) to keep the scan quick; the printed "
                "refit fits every sample") == "candidates fitted on 1 estimation sample in 6 (4335 of 26002) to keep the scan quick"
    # the key is the one the message was made with, whatever its words: plain text has none
    assert key_of("something that sits at its lower bound 0: reworded") == "other" and "other" in KEYS
    assert keyed(Message("any wording at all", "at-bound")) == "warning[at-bound]: any wording at all"


def test_a_model_files_warnings_keep_their_keys(tmp_path):
    """A fit's warnings are saved with their keys (``fit.warning_keys``) and read back as messages with
    them: ``validate`` repeats a model's fit warnings under the keys the fit gave them."""
    from endocal.models import load_model, make_model, save_model
    from endocal.models.data import HysteresisData

    cmd = np.tile(np.r_[np.linspace(0, 40, 15), np.linspace(40, 0, 15)], 2)
    model = make_model("pi", n_operators=8, axis="ap").fit(HysteresisData(cmd_deg=cmd, meas_deg=0.7 * cmd))
    keys = [key_of(w) for w in model.fit_report_.warnings]
    assert "few-samples" in keys, model.fit_report_.warnings
    save_model(model, tmp_path / "m.json")
    back = load_model(tmp_path / "m.json").fit_report_.warnings
    assert [key_of(w) for w in back] == keys and list(map(str, back)) == list(map(str, model.fit_report_.warnings))


@pytest.mark.parametrize("n, budget, kept", [(3, 5, 3), (5, 5, 5), (9, 5, 4)])
def test_capped_lines_say_how_many_more_explain_prints(n, budget, kept):
    lines = capped([f"w{i}" for i in range(n)], budget)
    assert len(lines) == min(n, budget) and lines[:kept] == [f"w{i}" for i in range(kept)]
    if n > budget:
        assert lines[-1] == f"... {n - kept} more warnings (--explain prints them)"


def test_validate_repeats_a_fit_that_did_not_converge_with_the_start_to_refit_from():
    from endocal.models import make_model
    from endocal.models.data import HysteresisData
    from endocal.validation.offline import validate_offline
    from endocal.views import validation_summary

    t = np.arange(0, 40, 0.05)
    cmd = 40 * np.sin(2 * np.pi * 0.1 * t)
    meas = 0.8 * cmd + 3 * np.sign(np.gradient(cmd)) + np.random.default_rng(0).normal(0, 0.2, t.size)
    model = make_model("linear", axis="ap").fit(HysteresisData(cmd_deg=cmd, meas_deg=meas, t_s=t), max_nfev=1)
    assert model.fit_report_.status == 0
    result = validate_offline(model, HysteresisData(cmd_deg=cmd, meas_deg=meas, t_s=t), model_path="m.json")
    assert key_of(result.model["fit_warnings"][0]) == "not-converged"
    line = next(x for x in validation_summary(result) if x.startswith("warning[not-converged]"))
    assert line.startswith("warning[not-converged]: the model's fit stopped before converging (") and \
        line.endswith("refit it from its own values with --start-from m.json"), line

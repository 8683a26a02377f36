"""Wear detected on the simulator (issue 34, How good): `endocal check` against the probe's models.

12 baseline checks of a probe (other seeds), then a worn probe: tendon slack up by 1 mm
(`[deadzone] slack_mm` 1.5 -> 2.5) or friction up by 30 % (`[tendon] mu` 0.2 -> 0.26). The
check must flag it within 3 checks. 50 checks of an unchanged probe raise at most one false
alarm (slow: 60 simulated checks; run with `pytest -m slow tests/test_check_wear.py`).

Each check is the real thing: the built-in check protocol played on the simulator (86 s of
rig time), scored against the fixture models, appended to a history in tmp_path.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from endocal.check.run import check_probe

FIXTURES = Path(__file__).parent / "fixtures" / "check"
MODELS = [FIXTURES / "ap.json", FIXTURES / "ml.json"]
#: The simulator's defaults (configs/sim-default.toml): slack 1.5 mm, mu 0.2.
WORN = {"slack": "[deadzone]\nslack_mm = 2.5\n", "friction": "[tendon]\nmu = 0.26\n"}


def _check(history, seed, sim_config=None):
    return check_probe(MODELS, "TEE-7", history, seed=seed, sim_config=sim_config)


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """A history of 12 checks of the unchanged probe (seeds 1000..1011)."""
    h = tmp_path_factory.mktemp("wear") / "history"
    states = [_check(h, 1000 + k).state for k in range(12)]
    assert states[:10] == ["baseline"] * 10  # the first 10 set the limits
    assert states[10:] == ["in control"] * 2
    return h


@pytest.mark.parametrize("wear", sorted(WORN))
def test_a_worn_probe_is_flagged_within_three_checks(baseline, tmp_path, wear):
    h = tmp_path / "history"
    shutil.copytree(baseline, h)
    cfg = tmp_path / "worn.toml"
    cfg.write_text(WORN[wear])
    results = [_check(h, 2000 + k, cfg) for k in range(3)]
    flagged = [r for r in results if r.state in ("drifting", "out of control")]
    assert flagged, [r.line() for r in results]
    # the first worn check already: a 1 mm slack or 30 % more friction moves the loop by tens of sigmas
    assert results[0].state == "out of control", results[0].line()
    assert results[0].exit_code == 4 and results[0].recalibrate
    # what moved: slack loses bend at both ends; friction widens the loop and lengthens the dead band
    first = results[0].flagged
    if wear == "slack":
        assert {"ap_bend_pos_deg", "ap_bend_neg_deg", "ml_bend_pos_deg", "ml_bend_neg_deg"} <= set(first)
    else:
        assert {"ap_loop_width_deg", "ml_loop_width_deg", "ap_dead_band_deg", "ml_dead_band_deg"} <= set(first)


@pytest.mark.slow
def test_fifty_checks_of_an_unchanged_probe_raise_at_most_one_false_alarm(tmp_path):
    h = tmp_path / "history"
    results = [_check(h, 3000 + k) for k in range(60)]
    judged = results[10:]  # the first 10 set the limits
    alarms = [r.line() for r in judged if r.state != "in control"]
    assert len(alarms) <= 1, alarms

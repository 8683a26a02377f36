"""``endocal effects`` end to end through Typer's test runner (endocal/cli/effects.py)."""

from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from endocal.cli.effects import effects
from endocal.models.effects import EFFECTS


@pytest.fixture
def app():
    a = typer.Typer()
    a.command()(effects)
    return a


def test_json_lists_every_effect_with_its_documentation(app):
    res = CliRunner().invoke(app, ["--json"])
    assert res.exit_code == 0, res.output
    entries = json.loads(res.stdout)["effects"]
    assert [e["name"] for e in entries] == list(EFFECTS)
    expected = {"envelope", "deadzone", "rate", "delay", "coupling", "drift", "creep", "load"}
    assert expected <= {e["name"] for e in entries}
    for e in entries:
        assert len(e["cause"]) > 20 and len(e["signature"]) > 20 and len(e["protocol"]) > 10, e["name"]
        assert e["kind"] in ("input", "filter", "output") and e["parameters"]
    by = {e["name"]: e for e in entries}
    assert by["load"]["usage"] == "load:COLUMN"
    assert by["creep"]["kind"] == "filter" and "t_s" in by["creep"]["needs"]
    assert by["delay"]["streamable"] is False and by["deadzone"]["streamable"] is True


def test_table_names_each_effect(app):
    res = CliRunner().invoke(app, [], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    for usage in ("envelope", "deadzone", "rate", "delay", "coupling", "drift", "creep", "load:COLUMN"):
        assert usage in res.stdout


def test_unknown_option_is_an_error(app):
    res = CliRunner().invoke(app, ["--bogus"])
    assert res.exit_code == 2

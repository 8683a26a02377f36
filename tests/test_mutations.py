"""No reader can be crashed: valid files, mutated as hand edits and broken copies leave them.

Every reader of a file a user gives endocal — model, planes and force JSON; protocol, path,
rig, simulator and CSV-map TOML; CSV logs; run folders (run.json, the motor and tracker
parts, the aligned table) — is fed seeded mutations of a valid file (:mod:`tests._mutate`):
a field deleted, added, retyped, NaN, infinite, huge; bytes cut, flipped, repeated. Each
must end with a result or one :class:`~endocal.errors.EndocalError` line, never another
exception; a command must end with exit code 0, or 2 and one line, and leave no output.

Two tiers, so ten thousand cases fit the suite's time: here, the bulk runs each reader and
what every command does first with what it read (a model predicts and inverts over its range,
a force model feeds the guard, a protocol renders its trajectory, a planes file compensates
one), a few ms a case; tests/test_mutations_commands.py sends a sample through the real
commands.

``ENDOCAL_MUTATIONS=K`` multiplies every count by K for a longer run on demand; the seed
is fixed, so a failure names its case (kind, index and the change) and replays.
"""

from __future__ import annotations

import traceback
import warnings
from pathlib import Path

import numpy as np
import pytest

from endocal.errors import EndocalError
from tests import _mutate
from tests._mutate import written as _written

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO / "tests" / "fixtures" / "mutate"
SCALE = _mutate.SCALE

#: Cases run per kind in this session (the module's last test checks the total).
COUNTS: dict[str, int] = {}


def _bulk(kind: str, cases, use) -> None:
    """Run ``use(path)`` on every mutated file; collect every exception that is not an EndocalError."""
    crashes = []
    n = 0
    for path, label in cases:
        n += 1
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                use(path)
        except EndocalError as exc:
            text = str(exc).strip()
            if not text or "\n" in text:
                crashes.append(f"{label}: not one line: {text!r}")
        except Exception as exc:  # noqa: BLE001 -- the point of the test: any other exception is a crash
            where = traceback.extract_tb(exc.__traceback__)[-1]
            crashes.append(f"{label}: {type(exc).__name__} at {Path(where.filename).name}:{where.lineno}: {exc}"[:300])
    COUNTS[kind] = COUNTS.get(kind, 0) + n
    assert not crashes, f"{len(crashes)} of {n} mutated {kind} files crashed a reader:\n" + "\n".join(crashes[:10])


# ----------------------------------------------------------------------------- models
@pytest.fixture(scope="module")
def model_files(tmp_path_factory) -> dict[str, Path]:
    """Valid model files of three bases, with input, output and filter effects, fitted on a shipped sample."""
    from endocal.models import make_model, save_model
    from endocal.runs.aligned import load_aligned
    from endocal.validation.data import axis_data

    d = tmp_path_factory.mktemp("models")
    record = load_aligned(REPO / "data_samples" / "sim-triangle")
    data = axis_data(record, "ap")
    # the provenance `fit hysteresis` writes: validate and report read it past the loader
    provenance = {"software": {"endocal": "0"}, "created_utc": "2026-11-28T00:00:00.000Z", "command": "endocal fit",
                  "cwd": str(REPO), "data": [{"path": str(record.source), "sha256": record.sha256}],
                  "planes": None, "planes_sha256": None, "probe": {"name": "tee", "bending_axes": ["ap", "ml"]}}
    out = {}
    for base, effects in (("pi", ["envelope", "delay"]), ("bspline", ["deadzone", "creep"]), ("linear", ["drift"])):
        model = make_model(base, effects, axis="ap").fit(data, max_nfev=20)
        out[base] = d / f"{base}.json"
        save_model(model, out[base], provenance=provenance)
    return out


_RECORDS: dict = {}


def _record():
    """The record the models were fitted on (loaded once)."""
    from endocal.runs.aligned import load_aligned

    if not _RECORDS:
        _RECORDS["sim-triangle"] = load_aligned(REPO / "data_samples" / "sim-triangle")
    return _RECORDS["sim-triangle"]


def _use_model(path: Path) -> None:
    """What every command does with a model file first: load, print, predict and invert over its range;
    and what `validate` and `report` read past the loader: the estimation data, planes and probe its
    provenance names, checked against a record."""
    from endocal.models import load_model
    from endocal.validation.estimation import plan_estimation

    model = load_model(path)
    for cv in ("auto", "rolling"):
        plan_estimation(model, [_record()], model_path=path, cv=cv)
    model.equation()
    lo, hi = model.cmd_range_deg_
    t_s = np.arange(120) * 0.05
    cmd = lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * 0.3 * t_s))
    y = model.predict(cmd, t_s=t_s)
    assert np.isfinite(y).all(), "a loaded model predicts non-finite angles"
    model.out_of_range = "clamp"
    assert np.isfinite(model.inverse(y, t_s=t_s)).all(), "a loaded model inverts to non-finite commands"


@pytest.mark.parametrize("base", ["pi", "bspline", "linear"])
def test_mutated_model_files_never_crash_a_reader(model_files, base, tmp_path):
    raw = model_files[base].read_bytes()
    _bulk("model JSON", _written(tmp_path, "m.json", _mutate.json_mutations, raw, 1, 1500 * SCALE), _use_model)


# ----------------------------------------------------------------------------- planes and force
def _use_planes(path: Path) -> None:
    from endocal.planes import load_planes
    from endocal.planes.from_runs import compensate_trajectory
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol

    probe = load_probe("tee")
    planes = load_planes(path)
    traj = load_protocol("triangle", {"cycles": 1, "amplitude_deg": 20.0}).trajectory(probe)
    out = compensate_trajectory(traj, probe, planes)
    assert all(np.isfinite(g).all() for g in out.goal.values()), "compensated goals are not finite"


def test_mutated_planes_files_never_crash_a_reader(tmp_path):
    raw = (FIXTURES / "planes.json").read_bytes()
    _bulk("planes JSON", _written(tmp_path, "planes.json", _mutate.json_mutations, raw, 3, 1000 * SCALE), _use_planes)


def _use_force(path: Path) -> None:
    from endocal.force import ForceGuard, check_guard_fits, load_force_model
    from endocal.probe import load_probe

    model = load_force_model(path)
    check_guard_fits(model, load_probe("tee"), 1.0)
    guard = ForceGuard(model, 1.0)
    lo, hi = model.theta_range_deg
    for k, theta in enumerate(np.linspace(lo, hi, 20)):
        guard.step(0.01 * k, float(theta), 10.0, 50.0, float(theta) + 1.0)


def test_mutated_force_models_never_crash_a_reader(tmp_path):
    raw = (FIXTURES / "force.json").read_bytes()
    _bulk("force JSON", _written(tmp_path, "force.json", _mutate.json_mutations, raw, 4, 1500 * SCALE), _use_force)


# ----------------------------------------------------------------------------- TOML files
def _use_protocol(path: Path) -> None:
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol

    load_protocol(path).trajectory(load_probe("tee"), seed=0)


def _use_path(path: Path) -> None:
    from endocal.probe import load_probe
    from endocal.protocols.paths import load_path, path_trajectory

    path_trajectory(load_path(path), load_probe("tee"))


def _use_rig(path: Path) -> None:
    from endocal.backends.hardware import HardwareConfig

    HardwareConfig.from_toml(path)


def _use_sim(path: Path) -> None:
    from endocal.sim.config import SimConfig

    SimConfig.from_toml(path)


def _use_map(path: Path) -> None:
    from endocal.runs.csvlog import read_map

    read_map(path)


TOML_FILES = [
    ("protocol", "protocols/triangle.toml", _use_protocol, 250),
    ("protocol", "protocols/damped-sine.toml", _use_protocol, 250),
    ("protocol", "protocols/chirp.toml", _use_protocol, 250),
    ("protocol", "protocols/random.toml", _use_protocol, 150),
    ("protocol", "protocols/sine-set.toml", _use_protocol, 150),
    ("path", "protocols/paths/circle-1.toml", _use_path, 300),
    ("path", "protocols/paths/raster.toml", _use_path, 200),
    ("rig", "configs/hardware-example.toml", _use_rig, 1000),
    ("sim config", "configs/sim-default.toml", _use_sim, 600),
    ("CSV map", "configs/csv-map.example.toml", _use_map, 500),
    ("CSV map", "configs/csv-map.angles.example.toml", _use_map, 500),
]


@pytest.mark.parametrize("kind,src,use,n", TOML_FILES, ids=[f[1].rsplit("/", 1)[-1] for f in TOML_FILES])
def test_mutated_toml_files_never_crash_a_reader(kind, src, use, n, tmp_path):
    raw = (REPO / src).read_bytes()
    name = Path(src).name
    (tmp_path / "paths").mkdir()  # a path file names a points CSV relative to itself: none is there
    _bulk(f"{kind} TOML", _written(tmp_path, name, _mutate.toml_mutations, raw, 5, n * SCALE), use)


def test_zz_the_count(request):
    """At least 10 000 mutated inputs ran (when the whole module ran), zero crashes."""
    selected = {item.name for item in request.session.items if item.module is request.module}
    if len(selected) < 20:
        pytest.skip("only part of the module ran")
    total = sum(COUNTS.values())
    print("\nmutated inputs run:", total, COUNTS)
    assert total >= 10_000 * SCALE, COUNTS

"""One probe check, from the protocol (or a recorded run) to the appended row and the probe's state.

``endocal check`` and :func:`endocal.api.check` call :func:`check_probe`; ``endocal check --run
RUN...`` and :func:`endocal.check.batch.check_runs` call :func:`prepare` / :func:`score_prepared`
/ :func:`commit` so the scoring can run as Dask tasks while the writes stay in one process.

Everything that can be refused is refused before a knob moves or a row is written: the probe ID,
the history folder (foreign files, an unreadable month file of this probe), the models (one per
axis, of this probe's type, no other probe's calibration), and a recorded run (of this probe).
"""

from __future__ import annotations

import json
import secrets
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from endocal.check.charts import BASELINE_CHECKS, ProbeCharts, probe_charts
from endocal.check.store import HistoryError, HistoryFolder, check_probe_id, models_json
from endocal.errors import ModelError, RunFormatError

#: Exit codes of ``endocal check`` by state (issue 34: 0 in control, 4 drifting or out of control).
EXIT_CODES = {"baseline": 0, "in control": 0, "drifting": 4, "out of control": 4}


@dataclass
class ProbeModels:
    """The models a check is scored against: ``{axis: model}`` with their files and hashes."""

    models: dict
    files: dict  # axis -> {"path", "sha256"}
    probe_type: str | None  # the probe preset the models were fitted on (provenance), if recorded

    @property
    def calibration(self) -> str:
        """The calibration's key: every axis' model hash (a new model is a new calibration)."""
        return ",".join(f"{a}:{self.files[a]['sha256'][:16]}" for a in sorted(self.files))


def load_probe_models(paths: Sequence) -> ProbeModels:
    """Load one model per bending axis.

    Raises
    ------
    ModelError
        No model, two of one axis, or models fitted on runs of different probe types.
    """
    from endocal.models import load_model
    from endocal.runs.format import sha256_of
    from endocal.runs.probes import probe_of

    if not paths:
        raise ModelError("no --model given: give the probe's hysteresis model, one per bending axis (endocal fit hysteresis)")
    models, files, types = {}, {}, {}
    for p in paths:
        p = Path(p)
        m = load_model(p)
        if m.axis in models:
            raise ModelError(f"two models of axis '{m.axis}' ({files[m.axis]['path']} and {p}): give one per bending axis")
        models[m.axis] = m
        files[m.axis] = {"path": str(p.resolve()), "sha256": sha256_of(p)}
        prov = getattr(m, "provenance_", {}) or {}
        probe = probe_of(prov)
        if probe is not None:
            types[str(p)] = probe["name"]
    if len(set(types.values())) > 1:
        (a, ta), (b, tb) = list(types.items())[:2] if len(types) == 2 else sorted(types.items())[:2]
        raise ModelError(f"{a} is a model of probe '{ta}', {b} of probe '{tb}': give the models of one probe")
    return ProbeModels(models, files, next(iter(types.values()), None))


@dataclass
class Prepared:
    """A check ready to score: its probe, models, run and what the history already holds."""

    probe_id: str
    history: HistoryFolder
    models: ProbeModels
    past: object  # DataFrame: this probe's rows
    run_dir: Path | None = None
    aligned: object = None
    source: str = "check"
    checked_utc: str = ""
    check_id: str = ""
    amplitude_deg: float | None = None
    protocol_sha256: str | None = None


@dataclass
class CheckResult:
    """One check: its figures, the probe's state and what to do.

    Attributes
    ----------
    probe_id, check_id, checked_utc : str
    state : str
        ``baseline`` (fewer than 10 checks since the calibration), ``in control``, ``drifting``
        (an EWMA beyond its limit) or ``out of control`` (a point beyond 3 sigma).
    figures : dict
        The check's figures (:mod:`endocal.check.scoring`).
    flagged : dict
        Figure -> ``drifting`` / ``out of control``.
    n_since_calibration : int
        Checks of this calibration, this one included.
    charts : ProbeCharts
    row_file, run_dir : Path
        The month file the row went to and the run folder kept beside it.
    recalibrate : list of str
        Commands that recalibrate the probe (when it is not in control).
    """

    probe_id: str
    check_id: str
    checked_utc: str
    state: str
    figures: dict
    flagged: dict
    n_since_calibration: int
    charts: ProbeCharts
    row_file: Path | None = None
    run_dir: Path | None = None
    recalibrate: list = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.state]

    def line(self) -> str:
        """The one line ``endocal check`` prints."""
        n = self.n_since_calibration
        if self.state == "baseline":
            return (f"{self.probe_id}: baseline, {n} of {BASELINE_CHECKS} checks since calibration "
                    f"(the control limits come from the first {BASELINE_CHECKS})")
        what = ""
        if self.flagged:
            what = ": " + ", ".join(f"{f} {s}" for f, s in self.flagged.items())
        return f"{self.probe_id}: {self.state}, {n} checks since calibration{what}"

    def to_dict(self) -> dict:
        return {"probe_id": self.probe_id, "check_id": self.check_id, "checked_utc": self.checked_utc,
                "state": self.state, "exit_code": self.exit_code, "n_since_calibration": self.n_since_calibration,
                "figures": self.figures, "flagged": self.flagged, "recalibrate": self.recalibrate,
                "row_file": None if self.row_file is None else str(self.row_file),
                "run_dir": None if self.run_dir is None else str(self.run_dir)}


def _now() -> datetime:
    return datetime.now(timezone.utc)


def _stamp(t: datetime) -> str:
    return t.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _new_check_id(t: datetime) -> str:
    return f"check-{t.strftime('%Y%m%dT%H%M%S')}-{secrets.token_hex(3)}"


def prepare(probe_id: str, history: str | Path, models: ProbeModels, *, probe_type: str | None = None) -> Prepared:
    """Refuse what cannot be checked, before anything moves or is written.

    Parameters
    ----------
    probe_id : str
    history : path
        The history folder (created on the first check).
    models : ProbeModels
    probe_type : str, optional
        The probe preset a new check runs on (``tee``...); None for a recorded run.

    Raises
    ------
    HistoryError
        A bad probe ID, foreign files in the history, or an unreadable month file of this probe.
    ModelError
        A model of another probe: fitted on runs of another probe type, or another probe's
        calibration in this history.
    """
    check_probe_id(probe_id)
    hist = HistoryFolder(history)
    read = hist.read(probe_id)
    if read.corrupt:
        raise HistoryError(f"{read.corrupt_line().split(': its checks')[0]}: no row appended (this probe's control "
                           "limits need every check); restore it from a backup or move it out of the history folder")
    past = read.rows
    past_type = str(past["probe_type"].iloc[-1]) if len(past) and "probe_type" in past else None
    for what, t in (("the models are", models.probe_type), ("the check runs on", probe_type)):
        if t is not None and past_type is not None and t != past_type:
            raise ModelError(f"{what} of probe type '{t}', but {probe_id}'s history in {history} is of a '{past_type}': "
                             f"give {probe_id}'s own models and probe")
    if models.probe_type is not None and probe_type is not None and models.probe_type != probe_type:
        raise ModelError(f"the models were fitted on a probe '{models.probe_type}', the check runs on a '{probe_type}' "
                         "(--probe): give the models of this probe")
    _refuse_other_probes_model(hist, probe_id, models, history)
    return Prepared(probe_id, hist, models, past)


def _refuse_other_probes_model(hist: HistoryFolder, probe_id: str, models: ProbeModels, where) -> None:
    """A model file that is another probe's calibration in this history is refused: every probe's tendons differ."""
    import pyarrow.parquet as pq

    ours = {v["sha256"]: k for k, v in models.files.items()}
    for probe_dir, (copy, months) in hist.sources(hist.validate()).items():  # a probe's one file where it is current
        other = probe_dir.name.removeprefix("probe=")
        if other == probe_id:
            continue
        texts = set()
        for f in [copy] if copy is not None else months:
            try:
                texts.update(pq.read_table(f, columns=["models"]).column("models").to_pylist())
            except Exception:  # noqa: BLE001  another probe's unreadable file is that probe's problem
                continue
        for text in texts:
            for rec in json.loads(text).values():
                if rec.get("sha256") in ours:
                    raise ModelError(f"{models.files[ours[rec['sha256']]]['path']} is probe {other}'s model (its checks "
                                     f"in {where} are scored against it), not {probe_id}'s: give {probe_id}'s own model")


def attach_run(prep: Prepared, run: str | Path) -> Prepared:
    """Score a check recorded earlier (or imported) instead of running one.

    Raises
    ------
    RunFormatError
        A run recorded for another probe ID, or on another probe type than the models'.
    """
    from endocal.runs.aligned import load_aligned
    from endocal.runs.probes import probe_of

    a = load_aligned(run)
    meta = a.meta or {}
    recorded = ((meta.get("protocol") or {}).get("check") or {}).get("probe_id")
    if recorded is not None and recorded != prep.probe_id:
        raise RunFormatError(f"{run} is a check of probe {recorded}, not {prep.probe_id}: give it with --probe-id "
                             f"{recorded}, or give a check of {prep.probe_id}")
    ptype = (probe_of(meta) or {}).get("name")
    past_type = str(prep.past["probe_type"].iloc[-1]) if len(prep.past) and "probe_type" in prep.past else None
    for other, whose in ((prep.models.probe_type, "the models were fitted on"), (past_type, f"{prep.probe_id}'s history is of")):
        if ptype is not None and other is not None and ptype != other:
            raise RunFormatError(f"{run} is a run of a probe '{ptype}', but {whose} a '{other}': give a check of "
                                 f"{prep.probe_id}")
    started = meta.get("started_utc")
    t = _now()
    if started:
        try:
            t = datetime.fromisoformat(str(started).replace("Z", "+00:00")).astimezone(timezone.utc)
        except ValueError:
            pass
    prep.aligned, prep.run_dir, prep.source = a, Path(run), "run"
    prep.checked_utc, prep.check_id = _stamp(t), _new_check_id(t)
    proto = meta.get("protocol") or {}
    prep.protocol_sha256 = proto.get("sha256")
    prep.amplitude_deg = (proto.get("params") or {}).get("amplitude_deg")
    if proto.get("name") is not None:  # an imported run records no protocol: its motion is the user's word
        from endocal.check.protocol import PROTOCOL_NAME, check_amplitude_deg

        expected = check_amplitude_deg(prep.models.models)
        if proto.get("name") != PROTOCOL_NAME or prep.amplitude_deg != expected:
            played = f"protocol '{proto.get('name')}'" + (f" at {prep.amplitude_deg:g} deg" if prep.amplitude_deg else "")
            raise RunFormatError(f"{run} played {played}, not the check at {expected:g} deg these models give: "
                                 "checks compare only as the same motion; record one with endocal check")
    if len(prep.past) and "check_id" in prep.past and (prep.past["run_sha256"] == a.sha256).any():
        raise RunFormatError(f"{run} is already in {prep.probe_id}'s history (the same run's streams): a check is "
                             "appended once")
    return prep


def excite_check(prep: Prepared, *, backend: str = "sim", probe: str = "tee", seed: int = 0,
                 sim_config=None, hardware_config=None, realtime: bool = False, progress=None) -> Prepared:
    """Play the check protocol (:mod:`endocal.check.protocol`) into a hidden folder of the history.

    Raises
    ------
    ModelError, ProtocolError, LimitError, ConfigError
        Before anything moves.
    """
    from endocal.backends.registry import make_backend
    from endocal.check.protocol import check_protocol
    from endocal.excite import run_excitation
    from endocal.probe import load_probe
    from endocal.runs.aligned import load_aligned

    probe_cfg = load_probe(probe)
    missing = [a for a in prep.models.models if a not in probe_cfg.bending_axes]
    if missing:
        raise ModelError(f"the model of axis '{missing[0]}' is not of a '{probe_cfg.name}' probe (axes "
                         f"{', '.join(probe_cfg.bending_axes)}): give this probe's models, or its --probe")
    proto = check_protocol(prep.models.models)
    trajectory = proto.trajectory(probe_cfg, seed=seed)
    trajectory.check_limits(probe_cfg)
    be = make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config)
    info = proto.to_dict()
    info["check"] = {"probe_id": prep.probe_id, "models": prep.models.files}
    t = _now()
    prep.check_id, prep.checked_utc = _new_check_id(t), _stamp(t)
    tmp = prep.history.root / f".{prep.check_id}.running"
    try:
        result = run_excitation(trajectory, be, probe_cfg, tmp, protocol_info=info, seed=seed, realtime=realtime,
                                command=f"endocal check --probe-id {prep.probe_id}", progress=progress)
        if result.status != "complete":
            raise RunFormatError(f"the check was {result.status} after {result.logged_s:.1f} s: no row appended; "
                                 "run the check again")
        prep.aligned = load_aligned(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    prep.run_dir, prep.source = tmp, "check"
    prep.amplitude_deg = float(info["params"]["amplitude_deg"]) if "params" in info else None
    prep.protocol_sha256 = info.get("sha256")
    return prep


def score_prepared(prep: Prepared) -> dict:
    """The check's figures (:func:`endocal.check.scoring.check_figures`)."""
    from endocal.check.scoring import check_figures

    return check_figures(prep.aligned, prep.models.models)


def commit(prep: Prepared, figures: Mapping) -> CheckResult:
    """Append the row (run folder beside it) and chart the probe's state.

    Raises
    ------
    HistoryError, OutputPathError
        Nothing appended.
    """
    import pandas as pd

    from endocal.check.summary import since_calibration
    from endocal.runs.probes import probe_of

    meta = getattr(prep.aligned, "meta", {}) or {}
    row = {"probe": prep.probe_id, "month": prep.checked_utc[:7], "check_id": prep.check_id,
           "checked_utc": prep.checked_utc, "calibration": prep.models.calibration,
           "probe_type": (probe_of(meta) or {}).get("name") or prep.models.probe_type or "",
           "models": models_json(prep.models.files), "source": prep.source,
           "run": f"probe={prep.probe_id}/month={prep.checked_utc[:7]}/_runs/{prep.check_id}",
           "run_sha256": prep.aligned.sha256, "protocol_sha256": prep.protocol_sha256 or "",
           "amplitude_deg": float("nan") if prep.amplitude_deg is None else float(prep.amplitude_deg)}
    row.update({k: float(v) for k, v in figures.items()})
    with prep.history.locked():
        past = prep.history.read(prep.probe_id).rows  # again under the lock: another writer may have appended
        rows = pd.concat([past, pd.DataFrame([row])], ignore_index=True).sort_values("checked_utc", kind="stable")
        cal = since_calibration(rows.reset_index(drop=True), prep.models.calibration)
        charts = probe_charts(prep.probe_id, cal, list(figures))
        k = int((cal["check_id"] == prep.check_id).to_numpy().nonzero()[0][0])
        state = charts.state_at(k)
        row["state"] = state
        target = prep.history.append(row, prep.run_dir, move_run=prep.source == "check")
    part = target.parent
    flagged = charts.flagged(k) if state not in ("baseline", "in control") else {}
    return CheckResult(prep.probe_id, prep.check_id, prep.checked_utc, state, dict(figures), flagged, k + 1, charts,
                       target, part / "_runs" / prep.check_id,
                       recalibrate_commands(prep) if flagged else [])


def recalibrate_commands(prep: Prepared) -> list[str]:
    """The commands that recalibrate the probe: a new estimation run per axis, the same model refitted on it,
    and the next check against the new models (which starts a new calibration's baseline)."""
    import shlex

    ptype = prep.models.probe_type or "tee"
    day = prep.checked_utc[:10]
    cmds, new = [], []
    for axis, m in sorted(prep.models.models.items()):
        lo, hi = m.cmd_range_deg_
        amp = int(min(-lo, hi))
        run = f"recal-{prep.probe_id}-{day}-{axis}"
        old = _shown(Path(prep.models.files[axis]["path"]))
        out = str(old.with_name(f"{old.stem}-{day}.json"))
        effects = ",".join(e.label for e in m.effects_)
        cmds.append(f"endocal excite damped-sine --axes {axis} --amplitude {amp} --probe {ptype} --out {shlex.quote(run)}")
        cmds.append(f"endocal fit hysteresis {shlex.quote(run)} --axis {axis} --model {m.base_name}"
                    + (f" --effects {effects}" if effects else "") + f" --out {shlex.quote(out)}")
        new.append(out)
    cmds.append("endocal check " + " ".join(f"--model {shlex.quote(p)}" for p in new)
                + f" --probe-id {prep.probe_id} --history {shlex.quote(str(prep.history.root))}")
    return cmds


def _shown(path: Path) -> Path:
    """A path as a command line shows it: relative to the working folder when inside it."""
    try:
        return path.relative_to(Path.cwd())
    except ValueError:
        return path


def check_probe(models: Sequence, probe_id: str, history: str | Path, *, run: str | Path | None = None,
                backend: str = "sim", probe: str = "tee", seed: int = 0, sim_config=None, hardware_config=None,
                realtime: bool = False, progress=None) -> CheckResult:
    """Check a probe: run the check protocol (or take ``run``), score it, append it, chart the state.

    Parameters
    ----------
    models : sequence of path
        The probe's hysteresis models, one per bending axis.
    probe_id : str
        The probe's own ID (serial number): its partition in the history.
    history : path
        The history folder.
    run : path, optional
        A check recorded earlier or imported; default: run the check now on ``backend``.
    backend, probe, seed, sim_config, hardware_config, realtime
        As for ``endocal excite``.

    Returns
    -------
    CheckResult

    Raises
    ------
    HistoryError, ModelError, RunFormatError, ProtocolError, LimitError, ConfigError, OutputPathError
        Nothing appended, nothing half-written.
    """
    if run is not None:
        from endocal.check.batch import check_runs

        return check_runs([run], history, probe_id=probe_id, models=models)[0]
    from endocal.probe import load_probe

    pm = load_probe_models(models)
    prep = prepare(probe_id, history, pm, probe_type=load_probe(probe).name)
    prep = excite_check(prep, backend=backend, probe=probe, seed=seed, sim_config=sim_config,
                        hardware_config=hardware_config, realtime=realtime, progress=progress)
    try:
        return commit(prep, score_prepared(prep))
    finally:
        if prep.run_dir is not None and prep.run_dir.name.endswith(".running"):
            shutil.rmtree(prep.run_dir, ignore_errors=True)

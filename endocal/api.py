"""The Python API: the calibration loop from a notebook, as objects.

`import endocal as ec` exports everything here (lazily: `import endocal` itself stays
instant, and each function imports the libraries it needs when called). Each function is a
thin layer over the library function its command calls, and each result renders from the
same result object the command prints, so a notebook and the command line cannot disagree:

```python
import endocal as ec

train = ec.load_run("demo-out/train")                               # endocal info
model = ec.fit([train, "demo-out/chirp"], axis="ap", model="pi",    # endocal fit hysteresis
               effects=["envelope"])
v = ec.validate(model, ["demo-out/test", "demo-out/check"])         # endocal validate
v.suggestions[0]            # the effect most likely missing, its gain and p-value
model2 = v.suggestions[0].refit()                                   # the refit validate prints
v2 = ec.validate(model2, ["demo-out/test", "demo-out/check"])       # compared with model
rep = ec.make_report([model, model2], ["demo-out/check"])            # endocal report
rep.plot("ladder-ap")
```

Every result has a short `repr` (the verdict first), `to_dict()` and `to_json()` (the
content of the command's `--json`) and `plot()` (a `matplotlib.figure.Figure` drawn by the
report's own figure functions, `endocal.report.figures`). Nothing here prints; bad input
raises an `endocal.errors.EndocalError` (also a `ValueError` or `OSError`) whose message is
one line: what was wrong, where, what to do.

| function         | returns      | command                    |
|------------------|--------------|----------------------------|
| `load_run`       | `Run`        | `endocal info`             |
| `run_protocol`   | `Run`        | `endocal excite`           |
| `fit`            | `Model`      | `endocal fit hysteresis`   |
| `load_model`     | `Model`      | (a model file)             |
| `validate`       | `Validation` | `endocal validate MODEL DATA` |
| `make_report`    | `Report`     | `endocal report`           |
| `fit_planes`     | `Planes`     | `endocal fit planes`       |
| `load_planes`    | `Planes`     | (a planes file)            |
| `fit_force`      | `ForceModel` | `endocal fit force`        |
| `check_probe`    | `Check`      | `endocal check`            |
| `history`        | `History`    | `endocal history DIR`      |

Why `make_report`, `run_protocol` and `check_probe` rather than `report`, `excite` and `check`: those
names are subpackages of `endocal` (`endocal.report`, `endocal.excite`, `endocal.check`), and Python binds a
subpackage to its parent's attribute once anything imports it, so `ec.report` would stop
being the function halfway through a session.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from pathlib import Path

from endocal.errors import ModelError, OutputExistsError

__all__ = [
    "BaseChange", "Check", "ForceModel", "History", "Model", "Planes", "Report", "Run", "Suggestion", "Validation",
    "check_probe", "fit", "fit_force", "fit_planes", "history", "load_model", "load_planes", "load_run", "make_report",
    "run_protocol", "use_effects", "validate",
]


def _json(d: dict) -> str:
    """Strict JSON (NaN and infinity as null, numpy scalars as numbers), indented."""
    from endocal.report.result import _clean

    return json.dumps(_clean(d), indent=2, allow_nan=False)


def _call(name: str, *args, **kwargs) -> str:
    """How a call is recorded in a file's provenance (`command`), e.g. `endocal.api.fit(['a'], axis='ap')`."""
    parts = [repr(a) for a in args] + [f"{k}={v!r}" for k, v in kwargs.items()]
    return f"endocal.api.{name}({', '.join(parts)})"


def _refuse_existing(path: Path, force: bool) -> None:
    if path.exists() and not force:
        raise OutputExistsError(f"{path} already exists: choose another path or pass force=True")


class _Result(ABC):
    """What every result shares: `to_json`, its `to_dict` as strict JSON."""

    @abstractmethod
    def to_dict(self) -> dict:
        """The result as plain data: what the command's `--json` prints."""

    def to_json(self) -> str:
        """`to_dict` as strict JSON (NaN as null), indented: what the command's `--json` prints."""
        return _json(self.to_dict())


class _Saved(_Result):
    """A result kept as a file (`save`, and `path` once saved or loaded); `_write` writes it."""

    path: Path | None = None

    @abstractmethod
    def _write(self, path: Path) -> None:
        """Write the file to `path` (refusing an existing one is `save`'s)."""

    def save(self, path: str | Path, *, force: bool = False) -> Path:
        """Write the file the command's `--out` writes (versioned JSON, whole or not at all).

        Parameters
        ----------
        path : str or Path
        force : bool
            Overwrite an existing file (by default it is refused).

        Returns
        -------
        Path
            `path`, now also the object's `path`.

        Raises
        ------
        OutputExistsError
            `path` exists and `force` is False.
        OutputPathError
            It cannot be written.
        """
        path = Path(path)
        _refuse_existing(path, force)
        self._write(path)
        self.path = path
        return path


# ---------------------------------------------------------------------------- runs
class Run(_Result):
    """A run folder or aligned table, loaded and checked (what `endocal info` shows).

    Made by `load_run` and `run_protocol`; every function that takes data takes a
    `Run` or a path.

    Attributes
    ----------
    path : Path
        The run folder or table file.
    axes : list of str
        Bending axes with both a command and a measured angle.
    table : pandas.DataFrame
        The aligned table: `t_s`, `<axis>_cmd_deg`, `<axis>_meas_deg`, extra columns.
    meta : dict
        `run.json` (empty for a bare table).
    probe : dict or None
        `name` and `bending_axes` of the probe it was recorded on (None for a bare table).
    protocol : str or None
        The protocol it played (or what was imported).
    sha256 : str
        Hash of the data, as model files record it.
    aligned : AlignedData
        The library's object (`endocal.runs.aligned.load_aligned`).
    """

    def __init__(self, aligned) -> None:
        from endocal.runs.probes import probe_of

        self.aligned = aligned
        self.path = Path(aligned.source)
        self.axes = list(aligned.axes)
        self.table = aligned.table
        self.meta = aligned.meta
        self.sha256 = aligned.sha256
        self.probe = probe_of(aligned.meta)
        proto = self.meta.get("protocol") if isinstance(self.meta.get("protocol"), dict) else {}
        self.protocol = proto.get("name")
        self._summary = None

    @property
    def summary(self):
        """`endocal.runs.summary.DataSummary`: rows, span, rate, ranges and reversals per axis."""
        if self._summary is None:
            from endocal.runs.summary import summarize

            self._summary = summarize(self.aligned)
        return self._summary

    def to_dict(self) -> dict:
        """What `endocal info RUN --json` prints."""
        return self.summary.to_dict()

    def __repr__(self) -> str:
        s = self.summary
        what = ", ".join(x for x in (f"{self.protocol} on {s.backend}" if self.protocol else "aligned table",
                                     f"probe {self.probe['name']}" if self.probe else "",
                                     f"status {s.status}" if s.status else "") if x)
        lines = [f"Run {str(self.path)!r}: {what}",
                 f"  {s.rows} samples, {s.duration_s:.4g} s at {s.rate_hz:.3g} Hz"]
        for a in s.axes:
            lines.append(f"  {a.axis}: command {a.cmd_range_deg[0]:.1f} .. {a.cmd_range_deg[1]:.1f} {a.drive_unit}, measured "
                         f"{a.meas_range_deg[0]:.1f} .. {a.meas_range_deg[1]:.1f} deg, {a.reversals} reversals")
        return "\n".join(lines)

    def _moving_axis(self, axis: str | None) -> str:
        import numpy as np

        if axis is not None:
            if axis not in self.axes:
                raise ModelError(f"{self.path}: no axis '{axis}' (it has {', '.join(self.axes)})")
            return axis
        spans = {a: float(np.ptp(self.aligned.cmd(a))) for a in self.axes}
        return max(self.axes, key=lambda a: spans[a])

    def plot(self, axis: str | None = None, kind: str = "loops"):
        """The measured record as the report draws it.

        Parameters
        ----------
        axis : str, optional
            Default: the axis whose command moves most.
        kind : {"loops", "time_series"}
            The hysteresis loop (measured angle against command), or command and measured
            angle over time.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from endocal.report import figures as F

        ax = self._moving_axis(axis)
        a = self.aligned
        title = f"{self.path.name} ({self.protocol or 'table'}), axis {ax}"
        if kind == "loops":
            return F.loops(a.cmd(ax), a.meas_deg(ax), {}, {}, title, a.drive_unit(ax))
        if kind == "time_series":
            return F.time_series(a.t_s, a.cmd(ax), a.meas_deg(ax), {}, {}, title, a.drive_unit(ax))
        raise ValueError(f"kind must be 'loops' or 'time_series', got {kind!r}")


def load_run(path: str | Path) -> Run:
    """Load a run folder (`endocal excite`, `import csv`, `import ros`) or an aligned table.

    Parameters
    ----------
    path : str or Path
        A run folder, or a `.parquet` / `.csv` aligned table (`t_s`,
        `<axis>_cmd_deg`, `<axis>_meas_deg`).

    Returns
    -------
    Run

    Raises
    ------
    RunFormatError
        The path does not exist, or what it holds breaks the run format (the message says
        which column or row).
    """
    from endocal.runs.aligned import load_aligned

    return Run(load_aligned(path))


def _aligned(data, what: str = "data") -> list:
    """Runs or paths (one, or a sequence) as the library's AlignedData, loaded once."""
    from endocal.runs.aligned import AlignedData, load_aligned

    if hasattr(data, "columns"):  # a DataFrame: iterating it would give its column names
        raise ModelError(f"{what}: a DataFrame; write it as an aligned table (df.to_csv('run.csv', index=False)) and "
                         "pass the path: a model file records its data by path and SHA-256")
    items = [data] if isinstance(data, (str, Path, Run, AlignedData)) else list(data)
    if not items:
        raise ModelError(f"no {what} given: pass run folders, aligned tables or Run objects")
    out = []
    for d in items:
        if isinstance(d, Run):
            out.append(d.aligned)
        elif isinstance(d, AlignedData):
            out.append(d)
        elif isinstance(d, (str, Path)):
            out.append(load_aligned(d))
        else:
            raise ModelError(f"{what}: expected a run folder, an aligned table or a Run, got {type(d).__name__}")
    return out


def run_protocol(protocol: str, out: str | Path, *, backend: str = "sim", probe: str = "tee", seed: int = 0,
                 sim_config: str | Path | None = None, hardware_config: str | Path | None = None,
                 realtime: bool = False, tip_load_n: float | None = None, force: bool = False, effects_file=None,
                 **params) -> Run:
    """Play an excitation protocol on the simulator (or the rig) and load the run it logged.

    What `endocal excite PROTOCOL --out OUT` does (without `--planes`, `--model` and
    the force guard, which stay on the command line).

    Parameters
    ----------
    protocol : str
        A protocol name (`endocal protocols`) or a protocol `.toml` file.
    out : str or Path
        The run folder to create.
    backend : {"sim", "hardware"}
    probe : str
        A probe preset (`tee`: axes ap, ml; `duodenoscope`: ud, lr) or a probe `.toml`.
    seed : int
        Seed of every random draw (simulator noise, random protocols; a protocol's own unset
        `seed` parameter takes it).
    sim_config, hardware_config : path, optional
        Simulator TOML (its effects and physics); rig TOML for `backend="hardware"`.
    realtime : bool
        Pace the simulator to the wall clock.
    tip_load_n : float, optional
        A known load hung at the tip (N), for `fit_force`.
    force : bool
        Replace `out` if it exists.
    effects_file : path or sequence of paths, optional
        Python files of one's own effects that `sim_config` hides (`[user_effects.NAME]`, :func:`use_effects`).
    **params
        Protocol parameters, e.g. `amplitude_deg=85, period_s=10, sample_rate_hz=25`
        (`endocal protocols show NAME` lists them; an unknown one raises).

    Returns
    -------
    Run

    Raises
    ------
    ProtocolError, ConfigError, LimitError
        Unknown protocol or parameter, bad configuration, goals beyond the probe's limits
        (checked before anything moves).
    OutputExistsError
        `out` exists and `force` is False.
    """
    from endocal.backends.registry import make_backend
    from endocal.excite import prepare_backend, run_excitation
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol

    use_effects(effects_file)
    probe_cfg = load_probe(probe)
    proto = load_protocol(protocol, overrides=dict(params) or None)
    trajectory = proto.trajectory(probe_cfg, seed=seed)
    trajectory.check_limits(probe_cfg)  # before any backend is built or anything moves
    be = make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config)
    be, record = prepare_backend(be, proto, probe_cfg, tip_load_n=tip_load_n)
    info = proto.to_dict()
    info.update(record)
    command = _call("run_protocol", protocol, str(out), backend=backend, probe=probe, seed=seed, **params)
    result = run_excitation(trajectory, be, probe_cfg, Path(out), protocol_info=info, seed=seed, realtime=realtime,
                            force=force, command=command)
    return load_run(result.run_dir)


# ---------------------------------------------------------------------------- models
class Model(_Saved):
    """A fitted hysteresis model of one axis, with how it was fitted (`endocal fit hysteresis`).

    Made by `fit`, `load_model` and `Suggestion.refit`. It prints as its
    equation with standard errors, then the fit's RMSE and warnings.

    Attributes
    ----------
    estimator : HysteresisModel
        The scikit-learn-style model itself (`predict`, `inverse`, `compensator`;
        `endocal.models`).
    axis, base : str
        Bending axis and base model (`pi`, `bspline`, `linear`).
    effects : list of str
        Its effect terms as `effects=` takes them (`["envelope", "delay"]`).
    settings : dict
        The base model's settings (`n_operators`, ...).
    params, stderr : dict of str to float
        Fitted parameters and their standard errors.
    equation : str
    rmse_deg : float
        RMSE of the fit on its own data (deg).
    warnings : list of str
        What the fit said: parameters at a bound or not pinned down, samples left out as
        glitches, records that did not start at rest.
    provenance : dict
        What the model file records (data paths and SHA-256, planes, software, time).
    path : Path or None
        The file it was loaded from or saved to.
    start_from : Model or None
        The model its fit started from (`Suggestion.refit` and `BaseChange.refit` set it); `validate`
        compares with it.
    """

    def __init__(self, estimator, *, provenance: dict | None = None, path: str | Path | None = None,
                 fit_info=None, start_from: Model | None = None) -> None:
        self.estimator = estimator
        self.provenance = dict(provenance if provenance is not None else getattr(estimator, "provenance_", None) or {})
        estimator.provenance_ = self.provenance  # validate finds the estimation data through it
        self.path = None if path is None else Path(path)
        self.start_from = start_from
        self._fit = fit_info

    axis = property(lambda self: self.estimator.axis, doc="Bending axis.")
    base = property(lambda self: self.estimator.base_name, doc="Base model name.")
    settings = property(lambda self: self.estimator.get_settings(), doc="Base-model settings.")
    params = property(lambda self: dict(self.estimator.params_), doc="Fitted parameters.")
    stderr = property(lambda self: dict(self.estimator.stderr_), doc="Standard errors of the parameters.")

    @property
    def effects(self) -> list[str]:
        """Effect terms as `effects=` takes them."""
        return [e.label for e in self.estimator.effects_]

    @property
    def label(self) -> str:
        """`base+effect+...`, how `validate` and the model ladder name a structure."""
        return "+".join([self.base, *self.effects])

    @property
    def equation(self) -> str:
        return self.estimator.equation()

    @property
    def fit_report(self):
        """`endocal.models.base.FitReport`: how the optimiser stopped, RMSE, samples."""
        return self.estimator.fit_report_

    @property
    def rmse_deg(self) -> float:
        rep = self.fit_report
        return float("nan") if rep is None else rep.rmse_deg

    @property
    def warnings(self) -> list[str]:
        rep = self.fit_report
        out = list(rep.warnings) if rep is not None else []
        if self._fit is not None:
            out += [w for w in (self._fit.glitches, self._fit.cut_start) if w]
        return out

    def to_dict(self) -> dict:
        """The model file's content: what `endocal fit hysteresis --json` prints (`endocal.models.io`)."""
        from endocal.models import model_to_dict

        d = model_to_dict(self.estimator)
        if self.provenance:
            d["provenance"] = self.provenance
        return d

    def _write(self, path: Path) -> None:
        from endocal.models import save_model

        save_model(self.estimator, path, provenance=self.provenance or None)

    def __repr__(self) -> str:
        rep = self.fit_report
        lines = [f"Model {self.label} of axis {self.axis}" + (f" ({self.path})" if self.path else ""),
                 f"  {self.equation}"]
        if rep is not None:
            if self._fit is not None and self._fit.duration_s > 0:
                span = f" ({self._fit.duration_s:.4g} s, {self._fit.rate_hz:.3g} Hz)"
            else:
                span = ""
            state = "converged" if rep.status > 0 else f"stopped before converging ({rep.message})"
            lines.append(f"  fit: RMSE {rep.rmse_deg:.3g} deg on {rep.n_samples} samples{span} from {rep.n_runs} "
                         f"record(s); {state}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def plot(self):
        """The report's figure of the fitted parameters with their 95 % intervals.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from endocal.report import figures as F
        from endocal.report.build import model_figure

        label = self.path.stem if self.path is not None else self.label
        return model_figure(label, self.estimator, F.palette([label])[label])[1]()


def _model(m, what: str = "model") -> Model:
    if isinstance(m, Model):
        return m
    if isinstance(m, (str, Path)):
        return load_model(m)
    raise ModelError(f"{what}: expected a Model or a model file, got {type(m).__name__}")


def use_effects(effects_file=None, classes: Sequence = ()) -> list[str]:
    """Load a user's effect files (`--effects-file`) and register effect or base classes given
    themselves; the names to write them by.

    Parameters
    ----------
    effects_file : path or sequence of paths, optional
        Python files of one's own effects and bases (`docs/how-to/add-effect.md`). Loading one
        runs it, as pytest runs a `conftest.py`.
    classes : sequence
        Effect names or classes (`effects=["delay", MyEffect]`); each class is checked and registered.

    Raises
    ------
    ModelError
        A file or class that cannot be used (one line naming the file and the effect).
    """
    from endocal.models.userfile import load_effects_files, register_user_class

    files = [] if effects_file is None else [effects_file] if isinstance(effects_file, (str, Path)) else list(effects_file)
    load_effects_files(files)
    out = []
    for c in classes:
        if isinstance(c, type):
            register_user_class(c)
            c = getattr(c, "name", None) or c.base_name
        out.append(c)
    return out


def load_model(path: str | Path, *, effects_file=None) -> Model:
    """Read a model file (`endocal fit hysteresis --out`, `Model.save`).

    `effects_file`: the user's effect files the model was fitted with (`use_effects`).

    Raises
    ------
    ModelError
        Missing or unreadable file, not a model file, unknown version or fields; a user's
        effect whose file is not given, or changed since the fit.
    """
    from endocal.models import load_model as _load

    use_effects(effects_file)

    return Model(_load(path), path=path)


def _planes_path(planes) -> Path | None:
    """`planes=` (a saved Planes or a path) as the file's path: a model records the planes it was
    fitted through by path and SHA-256, which `validate` and `report` read them back by."""
    if planes is None:
        return None
    if isinstance(planes, Planes):
        if planes.path is None:
            raise ModelError("planes: save the Planes first (planes.save('planes.json')): a model records the file "
                             "it was fitted through, and validate reads the planes back from it")
        return planes.path
    return Path(planes)


def fit(data, *, axis: str, model: str = "pi", effects: Sequence[str] | str = (), planes=None,
        start_from: Model | str | Path | None = None, settings: Mapping | None = None, effects_file=None,
        start_values: Mapping[str, float] | None = None) -> Model:
    """Fit a hysteresis model of one axis to runs (`endocal fit hysteresis`).

    Parameters
    ----------
    data : Run, path, or a sequence of them
        Estimation records, fitted together (one run each: operator states restart).
    axis : str
        Bending axis to model (`ap`, `ml`, `ud`, `lr`, a table's own name).
    model : {"pi", "bspline", "linear"}
        Base model: `pi` with `effects=["envelope"]` is the duodenoscope paper's modified
        Prandtl-Ishlinskii model (eqs. 5-8, analytic inverse eqs. 9-11); `bspline` the
        thesis's direction-dependent B-splines; `linear` a piecewise-linear model.
    effects : sequence of str or effect classes, or a comma-separated str
        Effect terms (`endocal effects` lists the catalogue), e.g. `["envelope", "delay"]`,
        `"load:sheath_wrap_deg"`, or a class of one's own (`[MyEffect]`, checked and registered).
    planes : Planes or path, optional
        Bending planes (`fit_planes`): measured angles are mapped into the twisted
        planes the knob drives first.
    start_from : Model or path, optional
        A fitted model of the same axis: the effects it has start at its values, and so does the
        base when it is `model`'s, else the base starts afresh (what `validate`'s refits do).
    settings : mapping, optional
        Base-model settings, e.g. `{"n_operators": 30}` (`--set` on the command line).
    effects_file : path or sequence of paths, optional
        Python files of one's own effects and bases (`--effects-file`, :func:`use_effects`).
    start_values : mapping, optional
        A second start for effect parameters by full name (`--start-value`), e.g.
        `{"deadzone_slack_deg": 2.4}`: the fit from it is made beside the one from `start_from` (or from
        scratch) and kept where it ends lower on the data (a suggestion's refit gives the values its
        candidate reached).

    Returns
    -------
    Model
        Not yet saved (`Model.save`); its provenance records the data as
        `validate` will look it up.

    Raises
    ------
    ModelError
        Unknown base, effect or setting; data no model can be fitted on; `start_from` of
        another axis.
    RunFormatError
        A missing or malformed record, a record without `axis`, or runs recorded on two
        probes.
    """
    from endocal.fitting import fit_hysteresis, fit_provenance

    model = use_effects(effects_file, [model])[0]
    if not isinstance(effects, str):
        effects = use_effects(None, list(effects))
    datas = _aligned(data)
    start = None if start_from is None else _model(start_from, "start_from")
    planes_path = _planes_path(planes)
    cal = None
    if planes_path is not None:
        from endocal.planes import load_planes as _load

        cal = _load(planes_path)
    result = fit_hysteresis(datas, axis, model, effects,
                            planes=cal, start_from=None if start is None else start.estimator,
                            start_values=dict(start_values or {}), **dict(settings or {}))
    command = _call("fit", [str(d.source) for d in datas], axis=axis, model=model,
                    effects=[e.label for e in result.model.effects_], **({"settings": dict(settings)} if settings else {}),
                    **({"start_values": dict(start_values)} if start_values else {}))
    prov = fit_provenance(result, command=command, planes_path=planes_path,
                          start_from_path=None if start is None else start.path)
    return Model(result.model, provenance=prov, fit_info=result, start_from=start)


# ---------------------------------------------------------------------------- validation
class _Proposal(_Result):
    """What `validate` proposes to refit (an effect, another base): the scan's object's `_FIELDS`, its `plan`, the
    shell `command` of that plan."""

    _FIELDS: tuple[str, ...] = ()

    def __init__(self, found, validation: Validation) -> None:
        self.plan = found.refit
        self._validation = validation
        for k in self._FIELDS:
            setattr(self, k, getattr(found, k))

    @property
    def command(self) -> str:
        """The refit as the shell command `endocal validate` prints (`endocal.shell.refit_command`)."""
        from endocal.shell import refit_command

        return refit_command(self.plan)


class Suggestion(_Proposal):
    """An effect the validation suggests adding, tested: its gain on held-out data and its p-value.

    Attributes
    ----------
    effect : str
        As `effects=` takes it (`deadzone`, `load:sheath_wrap_deg`).
    gain_pct : float
        How much the candidate lowers the validation (held-out) RMSE, percent.
    p_value : float
        Holm-corrected one-sided p-value of that gain (sign-flip test on half-cycle units).
    significant : bool
        `p_value` below alpha and the gain above the bar; otherwise it is listed on its
        gain alone and `evidence` says why.
    rmse_heldout_deg, base_rmse_heldout_deg : float
        Held-out RMSE with and without it (deg).
    evidence, cause, signature, caution : str
        Why it is (not) significant; the effect's physics and residual signature; what its
        fit left at a bound.
    plan : Refit
        What to refit (`endocal.validation.refit.Refit`): the data, base, resolved settings,
        effects, planes and start of the fit the scan scored, and `expected_rmse_deg`, the
        range to expect where the scan fitted a subsample; `refit()` makes it.
    command : str
        The same refit as the `endocal fit hysteresis` command line `validate` prints.
    suspect : Suspect
        The library's object (`endocal.validation.suspects.Suspect`).
    """

    _FIELDS = ("effect", "gain_pct", "p_value", "significant", "rmse_heldout_deg", "base_rmse_heldout_deg", "evidence",
               "cause", "signature", "caution")

    def __init__(self, suspect, validation: Validation) -> None:
        super().__init__(suspect, validation)
        self.suspect = suspect

    def to_dict(self) -> dict:
        """One entry of `suspects` in `endocal validate --json`: the suspect, with its refit's `command`."""
        from endocal.views import suspect_dict

        return suspect_dict(self.suspect)

    @property
    def effects(self) -> list[str]:
        """The refit's effects: the validated model's, then this one."""
        return list(self.plan.effects)

    def refit(self) -> Model:
        """Fit the validated model's structure with this effect added, as the scan scored it.

        On the estimation data the validation used (with `refit_on="all"` the validation
        data too; under rolling-origin cross-validation the validation data), through the same
        planes, with the same resolved settings (a `weights="auto"` fitted as `exponential`
        stays `exponential`), starting from the validated model: the fit whose command
        `endocal validate` prints.

        Returns
        -------
        Model
            Its `start_from` is the validated model, so `validate` shows the error
            falling.
        """
        p = self.plan
        return fit(list(p.data_paths), axis=p.axis, model=p.base, effects=list(p.effects), planes=p.planes_path,
                   start_from=self._validation.model, settings=p.settings, start_values=p.start_values)

    def summary(self) -> str:
        """One line: the effect, its gain and its p-value (or why it is not significant)."""
        stat = f"p = {self.p_value:.2g}" if self.significant else self.evidence
        return (f"add {self.effect}: {-self.gain_pct:+.0f} % validation RMSE "
                f"({self.base_rmse_heldout_deg:.3g} -> {self.rmse_heldout_deg:.3g} deg), {stat}")

    def __repr__(self) -> str:
        return f"Suggestion: {self.summary()}"


_KINDS = {"time_series": "ts-", "loops": "loops-", "residuals": "resid-", "regimes": "regime-"}


class BaseChange(_Proposal):
    """Another base the validation suggests, tested as a candidate: its gain on held-out data and its p-value.

    Attributes
    ----------
    base : str
        As `model=` takes it (`bouc-wen`, `linear`).
    added : tuple of str
        Effects the change brings beside the model's (empty: the model's effects alone).
    gain_pct, p_value, significant, rmse_heldout_deg, base_rmse_heldout_deg, evidence
        As for a `Suggestion` (the same paired test, Holm-corrected among the bases).
    return_point_memory : bool
        Whether the base returns to the branch it left after a small reversal inside the loop.
    plan : Refit
        What to refit: the data, base, effects and planes of the fit the scan scored; `refit()` makes it.
    command : str
        The same refit as the `endocal fit hysteresis` command line `validate` prints.
    candidate : BaseCandidate
        The library's object (`endocal.validation.bases.BaseCandidate`).
    """

    _FIELDS = ("base", "added", "gain_pct", "p_value", "significant", "rmse_heldout_deg", "base_rmse_heldout_deg",
               "evidence", "return_point_memory")

    def __init__(self, candidate, validation: Validation) -> None:
        super().__init__(candidate, validation)
        self.candidate = candidate

    def to_dict(self) -> dict:
        """One entry of `scan.bases` in `endocal validate --json`, with its refit's `command`."""
        from endocal.views import base_dict

        return base_dict(self.candidate)

    def refit(self) -> Model:
        """Fit this base with the effects the scan scored it with, on the data it was scored on, its effects
        starting from the validated model's values and the base afresh: the fit whose command `endocal
        validate` prints. Its `start_from` is the validated model, so `validate` shows the error falling."""
        p = self.plan
        return fit(list(p.data_paths), axis=p.axis, model=p.base, effects=list(p.effects), planes=p.planes_path,
                   start_from=self._validation.model, settings=p.settings, start_values=p.start_values)

    def summary(self) -> str:
        """One line: the base, its gain and its p-value (`base: bouc-wen lowers the validation RMSE by ...`)."""
        return self.candidate.line()

    def __repr__(self) -> str:
        return f"BaseChange: {self.summary()}"


class Validation(_Result):
    """A model held against measurements: how far off, where, what is missing (`endocal validate`).

    Made by `validate`, which runs the pipeline the command line runs
    (`endocal.validation.offline.validate_records`) and renders its one result with the same
    functions (`endocal.views`): its summary (`summary()`, also its `repr`) is what `endocal
    validate` prints, line for line, and `to_dict()` what `--json` prints, key for key.

    Attributes
    ----------
    model : Model
        The model validated.
    result : ValidationResult
        The library's object (`endocal.validation.offline.ValidationResult`), which every view renders.
    rmse_deg : float
        RMSE of the model on the validation data (deg); `metrics.ci["rmse_deg"]` its 95 %
        block-bootstrap interval.
    heldout_rmse_deg : float
        RMSE of the model's structure refitted on the estimation data (or rolling origin) and
        scored on the validation data: what the suggestions' gains compare against.
    metrics, regimes, residuals
        Error metrics, error by regime, residual tests.
    suggestions : list of Suggestion
        Effects most likely missing, best first (empty: nothing clears the bar).
    base_changes : list of BaseChange
        Other bases that clear the same bar, best first; `base_first` says the summary's next
        command is the first of them, not the first suggestion.
    untested : list of Pointer
        Effects the residual points at that the scan could not confirm, with the experiment
        that would (`endocal.validation.verdict.Pointer`).
    compare : Comparison or None
        The previous model's error beside this one's (`compare.old_path`: its file).
    compare_found : bool
        The previous model was not named but found: the model this one was refitted from.
    notes : list of str
        Each a `endocal.messages.Message`: its text, and its `key`.
    clean : bool
        Nothing is missing.
    next : NextOutcome or None
        With `validate(..., next=PATH)`: the protocol written (`.path`), its design
        (`.experiment`: what it tests, each effect's half-cycles and what the paired test
        needs at the gain seen), the `excite` command lines that record it (`.excite`), or
        why nothing was written (`.reason`) (`endocal.validation.next_experiment.NextOutcome`).
    request : ValidationRequest
        What was asked: the model's file, the records, `train`, `cv`, `planes`, `probe`,
        `refit_on`, and whether `next=` could design for this model (for the summary's next command).
    """

    def __init__(self, result, model: Model, *, records: Sequence) -> None:
        self.result = result
        self.model = model
        self._records = list(records)
        self.suggestions = [Suggestion(s, self) for s in result.suspects]
        self.base_changes = [BaseChange(b, self) for b in result.scan.base_suggestions]

    axis = property(lambda self: self.result.axis)
    metrics = property(lambda self: self.result.metrics)
    regimes = property(lambda self: self.result.regimes)
    residuals = property(lambda self: self.result.residuals)
    compare = property(lambda self: self.result.compare)
    clean = property(lambda self: self.result.clean)
    rmse_deg = property(lambda self: self.result.metrics.rmse_deg)
    heldout_rmse_deg = property(lambda self: self.result.scan.baseline_rmse_heldout_deg)
    untested = property(lambda self: list(self.result.pointers))
    notes = property(lambda self: list(self.result.notes))
    next = property(lambda self: self.result.next)
    request = property(lambda self: self.result.request)
    compare_found = property(lambda self: self.result.compare_found)
    base_first = property(lambda self: bool(self.base_changes) and self.result.scan.base_first)

    def to_dict(self) -> dict:
        """What `endocal validate MODEL DATA --json` prints, key for key (`endocal.views.validation_dict`)."""
        from endocal.views import validation_dict

        return validation_dict(self.result)

    def summary(self) -> list[str]:
        """The summary `endocal validate` prints, line for line (at most
        `endocal.views.SUMMARY_MAX_LINES`): how far off, where, what is missing, one keyed line per
        warning and note, the next command (`endocal.views.validation_summary`)."""
        from endocal.views import validation_summary

        return validation_summary(self.result)

    def __repr__(self) -> str:
        lines = self.summary()
        nx = None if self.next is None else self.next.experiment
        if self.next is not None:  # what the command line prints after the summary (endocal.cli.next_protocol)
            lines.append(f"next: {self.next.path} written ({nx.duration_s:.0f} s on probe {nx.probe}), tests "
                         f"{', '.join(nx.suspects)}; .next.excite records it" if nx is not None else
                         f"next: {self.next.reason}")
        return "\n".join(lines)

    def _record_figures(self):
        from endocal.report import figures as F
        from endocal.report.build import record_figures

        r = self.result
        label = r.model["label"]
        runs = [Run(d) for d in self._records]
        data = "+".join(run.path.name for run in runs)
        signal = ", ".join(dict.fromkeys(run.protocol or "table" for run in runs))
        return record_figures(data, signal, r.axis, r.hdata, {label: r.predicted_deg}, {label: r.regimes},
                              F.palette([label]))

    def plot(self, kind: str = "time_series"):
        """A figure of the validation data and the model, as the report draws each record.

        Parameters
        ----------
        kind : {"time_series", "loops", "residuals", "regimes"}
            Command, measured and predicted angle over time with the error below; the
            hysteresis loops, measured and predicted; the error against speed, command, the
            other axis and time; the error by regime of the motion.

        Returns
        -------
        matplotlib.figure.Figure
        """
        if kind not in _KINDS:
            raise ValueError(f"kind must be one of {', '.join(_KINDS)}, got {kind!r}")
        return next(draw for fig, draw in self._record_figures() if fig.id.startswith(_KINDS[kind]))()


def validate(model: Model | str | Path, data, *, train=None, compare: Model | str | Path | bool | None = None,
             cv: str = "auto", refit_on: str = "estimation", folds: int = 5, seed: int = 0, planes=None,
             load_columns: Sequence[str] | None = None, next: str | Path | None = None,
             probe: str | Path = "tee", effects_file=None) -> Validation:
    """Hold a model against validation records: how far off, where it fails, which effect is missing.

    What `endocal validate MODEL DATA...` does offline: error metrics with 95 %
    block-bootstrap intervals, the error by regime, residual tests, and every catalog effect
    the model lacks fitted on the estimation data (the records the model was fitted on,
    found through its provenance, or `train`) and scored on `data`, half-cycle by
    half-cycle, Holm-corrected.

    Parameters
    ----------
    model : Model or path
    data : Run, path, or a sequence of them
        Validation records (not used by the fit, for an honest score).
    train : Run, path, or a sequence of them, optional
        Estimation data (`--train`); default: what the model was fitted on.
    compare : Model, path or bool, optional
        A previous model, shown beside this one under the same scheme. Default (None): the
        model this one was refitted from (`Model.start_from`, else the file the refit
        command's naming points at, `M.json` for `M-EFFECT.json` or a base change's `M-BASE.json`), if
        any; False: none.
    cv : {"auto", "rolling", "split"}
        How effects are tested: the estimation/validation split when there is estimation
        data (`auto`), rolling-origin cross-validation on `data` alone (`rolling`), or
        require the split (`split`).
    refit_on : {"estimation", "all"}
        What `Suggestion.refit` fits on: the estimation data (as the candidates were
        scored), or the estimation and validation data (a final model, to be validated on a
        third record).
    folds : int
        Held-out blocks of the rolling-origin scan (2 or more).
    seed : int
        Seed of the bootstrap intervals.
    planes : Planes or path, optional
        Overrides the bending planes the model was fitted through.
    load_columns : sequence of str, optional
        Columns to try `load:COLUMN` on (default: every varying extra column).
    next : str or Path, optional
        Write the next experiment there (`--next`): the protocol `excite` runs that tests
        what this validation could not settle (`Validation.next` says what it tests, each
        effect's half-cycles needed at the gain seen, and the `excite` command lines);
        nothing is written when nothing is suspected (`Validation.next.reason` says so).
    probe : str or Path
        The probe the protocol is for when the records name none (`--probe`).
    effects_file : path or sequence of paths, optional
        Python files of one's own effects (`--effects-file`, :func:`use_effects`): the model's,
        and candidates the scan tests beside the catalogue's.

    Returns
    -------
    Validation

    Raises
    ------
    ModelError
        Bad `cv`, `refit_on` or `folds`; a model of an axis the data lacks; estimation
        data the model file names that is missing or changed; a `compare` model of another
        axis; records too short to validate on.
        With `next`: a fitted range no designed motion fits in (checked before validating).
    RunFormatError
        A missing or malformed record, or a validation run of another probe than the model's.
    """
    from endocal.validation.offline import validate_records

    use_effects(effects_file)
    m = _model(model)
    tables = _aligned(data, "validation data")
    train_paths = [] if train is None else [str(a.source) for a in _aligned(train, "estimation data")]
    old = m.start_from if compare is None else None if compare is False else _model(compare, "compare")
    result = validate_records(m.estimator, tables, model_path=m.path, train_paths=train_paths, cv=cv,
                              planes_path=_planes_path(planes), compare=None if old is None else old.estimator,
                              compare_path=None if old is None else old.path, find_previous=compare is None,
                              refit_on=refit_on, folds=folds, seed=seed, load_columns=load_columns, next_path=next,
                              probe=probe)
    return Validation(result, m, records=tables)


# ---------------------------------------------------------------------------- reports
class Report(_Result):
    """Models compared on records: metrics, paired tests, the model ladder, figures (`endocal report`).

    Made by `make_report`. Its `repr` is the report's summary.

    Attributes
    ----------
    report : endocal.report.Report
        The library's object, which the HTML page, `report.json` and the CSV render from.
    figures : list of ReportFigure
        Every figure: `id`, `section`, `title`, `caption` (and `figure`).
    files : dict or None
        `html`, `json`, `csv` paths when written (`out`).
    summary : list of str
        The summary sentences the command prints.
    """

    def __init__(self, report, files=None) -> None:
        self.report = report
        self.files = files

    figures = property(lambda self: list(self.report.figures))
    summary = property(lambda self: self.report.summary_lines())

    def to_dict(self) -> dict:
        """`report.json`'s content; `endocal report --json` prints its `summary`, `not_evaluated`,
        `metrics`, `ladder` and `notes`."""
        return self.report.to_dict()

    def to_json(self) -> str:
        return self.report.to_json()

    def write(self, out: str | Path, *, force: bool = False) -> dict:
        """Write the HTML page with its `.json` and `_metrics.csv` beside it.

        Returns
        -------
        dict
            `html`, `json`, `csv` paths.

        Raises
        ------
        OutputExistsError, OutputPathError
        """
        self.files = self.report.write(out, force=force)
        return self.files

    def __repr__(self) -> str:
        lines = self.summary
        shown = lines[:8] + ([f"... {len(lines) - 8} more line(s) (see .summary)"] if len(lines) > 8 else [])
        head = (f"Report: {len(self.report.models)} model(s) on {len(self.report.datas)} record(s), "
                f"{len(self.report.figures)} figures (.plot(ID); ids in .figures)")
        if self.files:
            head += f", written to {self.files['html']}"
        return "\n".join([head, *(f"  {s}" for s in shown)])

    def plot(self, which: int | str = 0):
        """One of the report's figures.

        Parameters
        ----------
        which : int or str
            Its index in `figures`, or its `id` (`ladder-ap`, `loops-check-ap`,
            `params-pi-envelope`, `planes`...).

        Returns
        -------
        matplotlib.figure.Figure
        """
        figs = self.report.figures
        if isinstance(which, int):
            if not -len(figs) <= which < len(figs):
                raise IndexError(f"figure {which}: the report has {len(figs)} figures")
            return figs[which].figure
        for f in figs:
            if f.id == which:
                return f.figure
        raise KeyError(f"no figure '{which}'; the report has {', '.join(f.id for f in figs)}")


def make_report(models, data, *, planes=None, out: str | Path | None = None, force: bool = False,
                bootstrap: int = 400, seed: int = 0, history: str | Path | None = None,
                probe_id: str | None = None, effects_file=None) -> Report:
    """Compare hysteresis models on records (`endocal report`).

    Every model is scored on every record of its axis; models are compared on per-half-cycle
    errors (Wilcoxon signed-rank for two, Friedman with Holm-corrected pairwise tests for
    more); every model structure is cross-validated for the model ladder.

    Parameters
    ----------
    models : Model, path, or a sequence of them
        Saved models are named by their file's stem, others by `base+effects`.
    data : Run, path, or a sequence of them
    planes : Planes or path, optional
        Adds the bending-plane figure before and after orthogonal compensation.
    out : str or Path, optional
        Write the HTML page there, with `NAME.json` and `NAME_metrics.csv` beside it
        (checked before any work).
    force : bool
        Overwrite those files.
    bootstrap, seed : int
        Block-bootstrap replicates and seed of the 95 % intervals (`validate`'s defaults).
    history : str or Path, optional
        A probe-check history (`check_probe`): adds the control charts of the probe checked
        against these models (`report --history`).
    probe_id : str, optional
        With `history`: the probe to chart, when its checks used other model files.
    effects_file : path or sequence of paths, optional
        Python files of one's own effects the models were fitted with (:func:`use_effects`).

    Returns
    -------
    Report
        `plot(figure)` draws one of its figures, `write(out)` the page with its side files.

    Raises
    ------
    ModelError, RunFormatError
        Missing or invalid inputs, models for axes no record has, or nothing that could be
        evaluated (the message lists why).
    OutputExistsError, OutputPathError
        `out` exists (without `force`) or cannot be written.
    """
    from endocal.report import build_report, side_files

    use_effects(effects_file)
    items = [models] if isinstance(models, (str, Path, Model)) else list(models)
    ms, names = [], []
    for m in map(_model, items):  # a saved model goes in by its file: named by its stem, its hash recorded
        ms.append(m.path if m.path is not None else m.estimator)
        names.append(str(m.path) if m.path is not None else m.label)
    if isinstance(planes, Planes):  # the figure only: each model reads its data through the planes it records
        planes = planes.path if planes.path is not None else planes.calibration
    rep = build_report(ms, _aligned(data), planes=planes, out=out, force=force, n_boot=bootstrap, seed=seed,
                       command=_call("make_report", names, out=None if out is None else str(out)), keep_figures=True,
                       history=history, history_probe=probe_id)
    return Report(rep, None if out is None else side_files(out))


# ---------------------------------------------------------------------------- planes and force
class Planes(_Saved):
    """A bending-plane calibration: the four half-planes' deviations, the twist delta and the
    orthogonal compensator (`endocal fit planes`; duodenoscope eqs. 1-4).

    Attributes
    ----------
    calibration : PlanesCalibration
        The library's object (`endocal.planes.calibration.PlanesCalibration`).
    deviation_deg, residual_deviation_deg : dict
        Per half-plane (`y+`, `y-`, `x+`, `x-`): the fitted deviation and what is left
        after compensation (deg).
    delta_deg : float
        The thesis's twist between the planes (deg).
    path : Path or None
        The file it was loaded from or saved to (`save`: `planes.json`, what `fit hysteresis
        --planes`, `excite --planes` and `report --planes` read).
    runs : list of Path
        The sweeps it was fitted on (where `plot` looks for the measured points).
    """

    def __init__(self, calibration, *, path: str | Path | None = None, runs: Sequence = ()) -> None:
        self.calibration = calibration
        self.path = None if path is None else Path(path)
        self.runs = [Path(r) for r in runs]

    deviation_deg = property(lambda self: dict(self.calibration.deviation_deg))
    residual_deviation_deg = property(lambda self: dict(self.calibration.residual_deviation_deg))
    delta_deg = property(lambda self: self.calibration.delta_deg)

    def to_dict(self) -> dict:
        """The planes file's content: what `endocal fit planes --json` prints."""
        return self.calibration.to_json()

    def _write(self, path: Path) -> None:
        from endocal.planes import save_planes

        save_planes(self.calibration, path, force=True)  # refused before, unless force

    def __repr__(self) -> str:
        return "Planes: " + str(self.calibration)

    def plot(self):
        """The report's bending-plane figure: measured sweeps seen down the probe axis, before
        and after compensation, with the fitted half-planes (duodenoscope fig. 8).

        Returns
        -------
        matplotlib.figure.Figure
        """
        from endocal.report.build import planes_figure
        from endocal.report.planes import planes_view

        view = planes_view(self.calibration, self.path, places=self.runs)
        return planes_figure(view)[1]()


def fit_planes(runs, *, after=(), bootstrap: int = 200, seed: int = 0) -> Planes:
    """Fit the bending planes from runs of the `planes` protocol (`endocal fit planes`).

    Parameters
    ----------
    runs : Run, path, or a sequence of them
        Run folders of single-knob sweeps of every half-plane.
    after : Run, path, or a sequence of them
        Sweeps recorded through the compensator: their deviations become the measured residuals.
    bootstrap, seed : int
        Bootstrap replicates over sweeps for the 95 % intervals, and their seed.

    Returns
    -------
    Planes

    Raises
    ------
    RunFormatError
        A missing path, an aligned table (the fit needs the tracker's poses), runs of two probes.
    """
    from endocal.planes.from_runs import calibrate_planes

    def paths(x):
        items = [x] if isinstance(x, (str, Path, Run)) else list(x)
        return [i.path if isinstance(i, Run) else Path(i) for i in items]

    before, comp = paths(runs), paths(after)
    cal, _ = calibrate_planes(before, after=comp or None, n_bootstrap=bootstrap, seed=seed)
    return Planes(cal, runs=[*before, *comp])


def load_planes(path: str | Path) -> Planes:
    """Read `planes.json` (`endocal fit planes --out`, `Planes.save`)."""
    from endocal.planes import load_planes as _load

    return Planes(_load(path), path=path, runs=[Path(path).parent])


class ForceModel(_Saved):
    """A contact-force model of one knob (`endocal fit force`; duodenoscope paper, eqs. 12-15).

    The report draws no figure of it, so it has no `plot`.

    Attributes
    ----------
    model : endocal.force.ForceModel
        The library's object (`predict`, the guard's evaluator).
    provenance : dict
    path : Path or None
        The file it was saved to (`save`: `force.json`, what `--force-model` reads).
    """

    def __init__(self, model, *, provenance: dict | None = None, path: str | Path | None = None) -> None:
        self.model = model
        self.provenance = dict(provenance or {})
        self.path = None if path is None else Path(path)

    def to_dict(self) -> dict:
        """The force-model file's content: what `endocal fit force --json` prints."""
        from endocal.force.io import force_model_to_dict

        return force_model_to_dict(self.model, self.provenance or None)

    def _write(self, path: Path) -> None:
        from endocal.force import save_force_model

        save_force_model(self.model, path, provenance=self.provenance or None, force=True)  # refused before

    def __repr__(self) -> str:
        m = self.model
        lines = [f"ForceModel {m}", f"  G = {m.g_:.3f} +- {m.g_se_:.3f} at knob {m.g_theta_ref_deg * m.side:+.0f} deg"]
        lines += [f"  held out {h.source}: load {h.load_n:.3f} N -> predicted {h.pred_mean_n:.3f} N ({h.error_pct:+.1f} %)"
                  for h in m.heldout_]
        return "\n".join(lines)


def fit_force(runs, *, axis: str | None = None, torque_constant_nm_per_a: float | None = None) -> ForceModel:
    """Fit the contact-force model from unloaded and loaded `force-calibration` runs (`endocal fit force`).

    Parameters
    ----------
    runs : Run, path, or a sequence of them
        At least one run with no tip load and two with known loads
        (`run_protocol("force-calibration", ..., tip_load_n=F)`).
    axis : str, optional
        Default: the one the runs' loads name.
    torque_constant_nm_per_a : float, optional
        Motor torque per current (N m/A); default: the simulator's, from `run.json`.

    Returns
    -------
    ForceModel

    Raises
    ------
    ModelError
        Too few unloaded or loaded runs; runs of different probes, axes or torque constants.
    """
    from endocal.force import fit_force as _fit
    from endocal.force.io import force_provenance

    items = [runs] if isinstance(runs, (str, Path, Run)) else list(runs)
    paths = [i.path if isinstance(i, Run) else Path(i) for i in items]
    model = _fit(paths, axis=axis, torque_constant_nm_per_a=torque_constant_nm_per_a)
    prov = force_provenance(paths, _call("fit_force", [str(p) for p in paths], axis=axis))
    return ForceModel(model, provenance=prov)


# ---------------------------------------------------------------------------- probe checks
class Check(_Result):
    """One probe check: its figures, the probe's state, what to do (`endocal check`).

    Attributes
    ----------
    result : endocal.check.run.CheckResult
        The library's result, which the command prints.
    state : str
        `baseline`, `in control`, `drifting` or `out of control`.
    figures : dict
        The check's figures (`ap_rmse_deg`, `ap_loop_width_deg`, `ap_dead_band_deg`,
        `ap_bend_pos_deg`, `ap_bend_neg_deg`, per axis).
    recalibrate : list of str
        The commands that recalibrate the probe (when it is not in control).
    """

    def __init__(self, result) -> None:
        self.result = result

    state = property(lambda self: self.result.state)
    figures = property(lambda self: self.result.figures)
    recalibrate = property(lambda self: self.result.recalibrate)

    def to_dict(self) -> dict:
        """What `endocal check --json` prints."""
        return self.result.to_dict()

    def __repr__(self) -> str:
        lines = [self.result.line(), *(f"  {c}" for c in self.recalibrate)]
        return "\n".join(lines)

    def plot(self):
        """The probe's control charts since its calibration, this check the last point.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from endocal.report.checks import charts_figure

        return charts_figure(self.result.charts)


def check_probe(models, probe_id: str, history: str | Path, *, run: str | Path | None = None, backend: str = "sim",
                probe: str = "tee", seed: int = 0, sim_config: str | Path | None = None,
                hardware_config: str | Path | None = None, realtime: bool = False) -> Check:
    """Check a probe's calibration: run the built-in check protocol, score it, append it to the history.

    What `endocal check --model ... --probe-id ID --history DIR` does.

    Parameters
    ----------
    models : path or Model, or a sequence of them
        The probe's hysteresis models (saved files: the history records them by path and
        SHA-256), one per bending axis.
    probe_id : str
        The probe's own ID (serial number): its partition `probe=ID` of the history.
    history : str or Path
        The fleet's history folder (created on the first check).
    run : str or Path, optional
        A check recorded earlier or imported, scored instead of running one.
    backend, probe, seed, sim_config, hardware_config, realtime
        As for `run_protocol`.

    Returns
    -------
    Check

    Raises
    ------
    HistoryError, ModelError, RunFormatError
        A bad probe ID, a history folder with foreign files or an unreadable month file of this
        probe, a model of another probe, a run of another probe: nothing is appended.
    """
    from endocal.check.run import check_probe as _check

    items = [models] if isinstance(models, (str, Path, Model)) else list(models)
    paths = []
    for m in map(_model, items):
        if m.path is None:
            raise ModelError(f"the {m.axis} model is not saved: save it (model.save('{m.axis}.json')) and pass it, "
                             "the history records each check's models by file and SHA-256")
        paths.append(m.path)
    return Check(_check(paths, probe_id, history, run=run, backend=backend, probe=probe, seed=seed,
                        sim_config=sim_config, hardware_config=hardware_config, realtime=realtime))


class History(_Result):
    """A fleet's check history (`endocal history DIR`): the rows, every probe's state and its control charts.

    Attributes
    ----------
    rows : pandas.DataFrame
        Every check of every probe (`probe`, `month`, `checked_utc`, `state`, the figures...).
    table : pandas.DataFrame
        Every probe's last check and state, one row per probe.
    charts : dict of str -> endocal.check.charts.ProbeCharts
        Each probe's control charts since its calibration (`.charts[ID].charts[FIGURE]`:
        the individuals, moving-range and EWMA series with their limits).
    corrupt : list of (Path, str)
        Month files that could not be read (their rows are missing; the rest is read).
    """

    def __init__(self, fleet) -> None:
        self.fleet = fleet
        self.rows = fleet.rows
        self.table = fleet.table()
        self.charts = {p: fleet.charts(p) for p in fleet.probes}
        self.corrupt = list(fleet.corrupt)

    def to_dict(self) -> dict:
        """The table (`endocal history DIR --json`) and the unreadable files."""
        return {"probes": self.table.to_dict(orient="records"),
                "corrupt": [{"path": str(p), "error": why} for p, why in self.corrupt]}

    def __repr__(self) -> str:
        states = self.table["state"].value_counts().to_dict() if len(self.table) else {}
        head = (f"History {self.fleet.root}: {len(self.table)} probe(s), {len(self.rows)} check(s)"
                + "".join(f", {n} {s}" for s, n in states.items()))
        lines = [head, *(f"  {r.probe}: {r.state}, {r.checks_since_calibration} checks since calibration"
                         for r in self.table.itertuples())]
        if self.corrupt:
            lines.append(f"  unreadable: {self.fleet.corrupt_line()}")
        return "\n".join(lines)

    def sql(self, query: str):
        """One read-only SELECT over the view `checks` (DuckDB; `endocal history DIR --sql`).

        Returns
        -------
        pandas.DataFrame
        """
        from endocal.check.sql import query as _query

        return _query(self.fleet.root, query).rows

    def plot(self, probe_id: str | None = None):
        """A probe's control charts (`endocal history DIR --probe ID --plot FILE.png`).

        Parameters
        ----------
        probe_id : str, optional
            Default: the only probe.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from endocal.report.checks import charts_figure

        if probe_id is None:
            if len(self.charts) != 1:
                raise ModelError(f"the history holds {len(self.charts)} probes: name one ({', '.join(self.charts)})")
            probe_id = next(iter(self.charts))
        if probe_id not in self.charts:
            self.fleet.probe_rows(probe_id)  # raises, naming the probes there are
        return charts_figure(self.charts[probe_id])


def history(path: str | Path) -> History:
    """Read a fleet's check history (`endocal history DIR`).

    Parameters
    ----------
    path : str or Path
        The history folder (`endocal check --history DIR`).

    Returns
    -------
    History
        `.rows` (a DataFrame of every check), `.table`, `.charts`, `.plot(ID)`, `.sql(...)`.

    Raises
    ------
    HistoryError
        No such folder, or foreign files in it. An unreadable month file is not raised:
        `History.corrupt` names it, and the rest is read.
    """
    from endocal.check.summary import read_history

    return History(read_history(path))

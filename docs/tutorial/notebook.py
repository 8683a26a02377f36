# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # The calibration loop from a notebook
#
# The same loop as `make demo`, from Python: excite a simulated TEE probe, fit the duodenoscope
# paper's modified Prandtl-Ishlinskii model, hold it against records it never saw, add the
# effect the validation says is missing, and watch the error fall. Every object here is what
# the matching `endocal` command prints, as an object: a short `repr`, `.to_dict()` (the
# command's `--json`), and `.plot()` (the report's figures).
#
# The records are short (25 Hz, about a minute each), so the whole notebook runs in about a
# minute; `make demo` records the full-length protocols.
#
# This page is kept as a [jupytext](https://jupytext.readthedocs.io) script
# (`docs/tutorial/notebook.py`) and executed by the test suite, which keeps what each cell
# shows (its repr, its figure) for this page: what you see under a cell is what the code did
# when the suite last ran it, so your own run should match it. Open it in Jupyter with
# `jupytext --to ipynb docs/tutorial/notebook.py`.

# %%
from pathlib import Path

import endocal as ec

out = Path("tutorial-out")  # every run and model of this notebook goes here

# %% [markdown]
# ## 1. Excite the probe
#
# `ec.run_protocol` plays a protocol on the simulator and loads the run folder it logged
# (`endocal excite`). Two *estimation* runs to fit on: the paper's damped sine and a chirp
# (several speeds tell a delay from speed-dependent friction); two *validation* runs that no
# fit will see: a band-limited random input and the paper's triangle.

# %%
fast = {"sample_rate_hz": 25}
train = ec.run_protocol("damped-sine", out / "train", seed=2, amplitude_deg=85, period_s=10, force=True, **fast)
chirp = ec.run_protocol("chirp", out / "chirp", seed=4, amplitude_deg=50, duration_s=40, f0_hz=0.05, force=True,
                        **fast)
test = ec.run_protocol("random", out / "test", seed=3, amplitude_deg=60, duration_s=40, force=True, **fast)
check = ec.run_protocol("triangle", out / "check", seed=5, amplitude_deg=50, period_s=10, force=True, **fast)
train

# %% [markdown]
# A run you recorded yourself, or imported with `endocal import csv`, loads the same way:
# `ec.load_run("path/to/run")`. Its hysteresis loop:

# %%
train.plot()

# %% [markdown]
# ## 2. Fit the paper's model
#
# `pi` with the `envelope` effect is the duodenoscope paper's modified PI model (eqs. 5-8).
# The model prints as its equation, parameters with standard errors.

# %%
model = ec.fit([train, chirp], axis="ap", model="pi", effects=["envelope"])
model

# %% [markdown]
# ## 3. Validate: how far off, where, what is missing
#
# `ec.validate` holds the model against the validation runs, refits every effect of the
# catalogue the model lacks on the estimation runs, and scores each on the validation runs,
# half-cycle by half-cycle. The verdict comes first.

# %%
v = ec.validate(model, [test, check])
v

# %% [markdown]
# The suggestion, with its gain on data the fit never saw and its Holm-corrected p-value:

# %%
v.suggestions[0]

# %% [markdown]
# What the suggestions rest on: the error against knob speed, command, the other axis and time.
# A step at zero speed points to a dead zone (tendon slack), a slope against speed to a delay
# or speed-dependent friction.

# %%
v.plot("residuals")

# %% [markdown]
# ## 4. Add the effect, validate again, watch the error fall
#
# `refit()` fits the model with the suggested effect, on the estimation runs, starting from
# the model it was validated as (the fit the validation scored). The new validation compares
# itself with the model it came from.

# %%
model2 = v.suggestions[0].refit()
v2 = ec.validate(model2, [test, check])
v2

# %% [markdown]
# Once more, with what this validation suggests:

# %%
model3 = v2.suggestions[0].refit()
model3

# %%
model3.plot()

# %% [markdown]
# ## 5. Keep the model, compare the models
#
# A model file is versioned JSON, the same as `endocal fit hysteresis --out` writes;
# `to_dict()` is its content (what `--json` prints).

# %%
path = model3.save(out / f"{model3.label}.json", force=True)
again = ec.load_model(path)
{key: again.to_dict()[key] for key in ("axis", "base", "effects", "cmd_range_deg")}

# %% [markdown]
# `ec.make_report` is `endocal report`: every model on every record, compared with paired
# tests, and the model ladder, each step's held-out error with its interval. Pass
# `out="report.html"` to write the HTML page.

# %%
rep = ec.make_report([model, model2, model3], [check, test], bootstrap=100)
rep

# %%
rep.plot("ladder-ap")

"""Probe checks after calibration day (issue 34): is this probe still within its calibration?

One module per concept:

- :mod:`~endocal.check.protocol`: the fixed, built-in check protocol, inside the model's fitted range;
- :mod:`~endocal.check.scoring`: one check scored against the probe's models (validation RMSE,
  loop width, dead band, bend reached each way);
- :mod:`~endocal.check.charts`: individuals/moving-range and EWMA control charts, and the state;
- :mod:`~endocal.check.store`: the history, a hive-partitioned Parquet dataset (``probe=ID/month=YYYY-MM``);
- :mod:`~endocal.check.run`: a check from protocol (or recorded run) to appended row;
- :mod:`~endocal.check.batch`: many probes' recorded checks scored as Dask tasks;
- :mod:`~endocal.check.summary`: a history read back: every probe's state, one probe's charts;
- :mod:`~endocal.check.sql`: DuckDB over the history, read-only;
- :mod:`~endocal.check.extras`: the optional ``[fleet]`` extra (DuckDB, Dask).

The charts as a figure are the report's (:mod:`endocal.report.checks`): data flows from the
checks to the report, never back.
"""

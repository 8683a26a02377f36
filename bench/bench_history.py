"""`endocal history --sql` over a fleet's history (issue 34). Prints; asserts nothing.

Target: a query over 100 probes x 2 years of daily checks (73,000 rows in 2,400 month files,
simulated rows) takes <= 1 s. Measured in the same run against the plain reference, pandas
reading the same dataset (``pandas.read_parquet(DIR)``, pyarrow's hive discovery) and answering
the same question:

1. the query alone (`endocal.check.sql.query`: the folder's layout checked, the view built,
   DuckDB run), for a fleet's question: which probes' dead band grew more than 20 % in 30 days;
2. a plain count over the view;
3. the whole command, `endocal history DIR --sql ...` in a fresh process (start-up included).

The rows are written straight in the store's layout (``probe=ID/month=YYYY-MM/checks.parquet``,
the columns a check appends, and each probe's one-file copy as an append leaves it), with random
figures: what the query reads, not how the checks came about.

Run: ``.venv/bin/python bench/bench_history.py [N_PROBES] [DAYS]``
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from endocal.check.scoring import FIGURES
from endocal.check.store import ROWS_FILE, HistoryFolder
from endocal.runs.format import atomic_write_bytes, parquet_bytes

QUESTION = """
WITH recent AS (
  SELECT probe, checked_utc, ap_dead_band_deg AS db FROM checks
  WHERE CAST(checked_utc AS TIMESTAMP) >= (SELECT max(CAST(checked_utc AS TIMESTAMP)) FROM checks) - INTERVAL 30 DAY)
SELECT probe, arg_min(db, checked_utc) AS first_deg, arg_max(db, checked_utc) AS last_deg,
       arg_max(db, checked_utc) / arg_min(db, checked_utc) - 1 AS growth
FROM recent GROUP BY probe HAVING growth > 0.2 ORDER BY growth DESC
"""


def write_fleet(root: Path, n_probes: int, days: int) -> int:
    rng = np.random.default_rng(34)
    t0 = pd.Timestamp("2024-11-28T08:00:00Z")
    times = t0 + pd.to_timedelta(np.arange(days), unit="D")
    n_rows = 0
    for p in range(n_probes):
        pid = f"TEE-{p:04d}"
        models = json.dumps({a: {"path": f"/lab/models/{pid}-{a}.json", "sha256": f"{p:064x}"} for a in ("ap", "ml")})
        wear = rng.uniform(0, 0.004)  # deg of dead band per day, some probes wear faster
        df = pd.DataFrame({
            "check_id": [f"check-{t:%Y%m%dT%H%M%S}-{p:06x}" for t in times],
            "checked_utc": [t.isoformat(timespec="milliseconds").replace("+00:00", "Z") for t in times],
            "calibration": f"ap:{p:016x},ml:{p:016x}", "probe_type": "tee", "models": models, "source": "check",
            "run": [f"probe={pid}/month={t:%Y-%m}/_runs/check-{t:%Y%m%dT%H%M%S}" for t in times],
            "run_sha256": "0" * 64, "protocol_sha256": "0" * 64, "amplitude_deg": 45.0})
        for a in ("ap", "ml"):
            base = {"rmse_deg": 1.2, "loop_width_deg": 6.2, "dead_band_deg": 9.6, "bend_pos_deg": 28.8, "bend_neg_deg": 27.9}
            for f in FIGURES:
                df[f"{a}_{f}"] = base[f] + 0.05 * rng.standard_normal(days)
            df[f"{a}_dead_band_deg"] += wear * np.arange(days)
        if p % 37 == 5:  # three probes whose tendons slackened last month: the query must find them
            df["ap_dead_band_deg"] += np.clip(np.arange(days) - (days - 30), 0, None) * 0.1
        df["state"] = "in control"
        month = df["checked_utc"].str[:7]
        for m, part in df.groupby(month):
            atomic_write_bytes(root / f"probe={pid}" / f"month={m}" / ROWS_FILE, parquet_bytes(part.reset_index(drop=True)))
            n_rows += len(part)
        HistoryFolder(root).refresh_probe_file(root / f"probe={pid}")  # as every append keeps it
    return n_rows


def best_of(fn, repeat=5) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def pandas_answer(root: Path) -> pd.DataFrame:
    df = pd.read_parquet(root, columns=["probe", "checked_utc", "ap_dead_band_deg"])
    t = pd.to_datetime(df["checked_utc"])
    recent = df[t >= t.max() - pd.Timedelta(days=30)].sort_values("checked_utc")
    g = recent.groupby("probe", observed=True)["ap_dead_band_deg"]
    growth = g.last() / g.first() - 1
    return growth[growth > 0.2].sort_values(ascending=False)


def main() -> None:
    from endocal.check.sql import query

    n_probes = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    days = int(sys.argv[2]) if len(sys.argv) > 2 else 730
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "history"
        t0 = time.perf_counter()
        n = write_fleet(root, n_probes, days)
        files = len(list(root.glob("*/*/*.parquet")))
        print(f"history: {n_probes} probes x {days} days = {n:,} rows in {files:,} month files "
              f"(written in {time.perf_counter() - t0:.1f} s)")
        t_q, res = best_of(lambda: query(root, QUESTION))
        t_c, cnt = best_of(lambda: query(root, "SELECT count(*) AS n FROM checks"))
        t_p, ref = best_of(lambda: pandas_answer(root))
        same = sorted(res.rows["probe"]) == sorted(map(str, ref.index))
        print(f"query 'dead band grew > 20 % in 30 days': {t_q * 1e3:7.1f} ms, {len(res.rows)} probes "
              f"(pandas finds the same: {same})")
        print(f"query 'count(*)':                       {t_c * 1e3:7.1f} ms, {int(cnt.rows['n'].iloc[0]):,} rows")
        print(f"pandas.read_parquet(DIR) + the same:    {t_p * 1e3:7.1f} ms   (reference)")
        print(f"ratio query / pandas:                   {t_q / t_p:7.2f}")
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "endocal", "history", str(root), "--sql", QUESTION],
                              capture_output=True, text=True)
        t_cli = time.perf_counter() - t0
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "endocal", "--version"], capture_output=True, text=True)
        t_start = time.perf_counter() - t0
        print(f"endocal history DIR --sql (a fresh process): {t_cli:.2f} s, exit {proc.returncode} "
              f"(of which the interpreter and endocal's start-up: {t_start:.2f} s)")


if __name__ == "__main__":
    main()

"""Mutations of valid input files, as a hand edit, a half-synced copy or a flaky disk leaves them.

Each generator takes a valid file's content and a seeded generator and yields
``(label, bytes)``: the label says what was changed, so a failing case can be
replayed from its message alone. Two families:

- **structured**: the file is parsed (JSON, TOML, CSV), one value or field is changed
  — deleted, added, turned into another type, NaN, infinity, a huge or negative
  number, an empty string or list — and the file is written back;
- **bytes**: truncation at a random length, a flipped byte, a deleted or repeated span.

A plain seeded generator rather than hypothesis: the inputs are mutations of one known
file, not values drawn from a type, so the count of cases run is exact and every case
is named by its seed and label (hypothesis would shrink a failure, but the label
already is the smallest description of the change).
"""

from __future__ import annotations

import io
import json
import math
import os
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

#: ``ENDOCAL_MUTATIONS=K`` multiplies every count of cases (a longer run on demand).
SCALE = int(os.environ.get("ENDOCAL_MUTATIONS", "1"))

#: Values a field may be turned into: other types, non-finite and extreme numbers.
ODD_VALUES: list = [None, True, "x", "", [], {}, [1, 2], {"a": 1}, 0, -1, 1e308, -1e308, 1e-308, math.nan,
                    math.inf, -math.inf, 3, 0.5, -0.5, 2**63]


def _paths(node, prefix=()) -> list[tuple]:
    """Every path into a parsed JSON/TOML document (dict keys and list indices)."""
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node[:8]):  # long arrays: their first entries stand for the rest
            out += _paths(v, (*prefix, i))
    return out


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def mutate_document(doc, rng: np.random.Generator, under: tuple[str, ...] = ()) -> tuple[str, object]:
    """One structured change of a parsed document (a deep copy is changed, not ``doc``); with
    ``under``, of a field below one of those top-level keys only."""
    doc = json.loads(json.dumps(doc))
    paths = [p for p in _paths(doc) if not under or p[0] in under] or _paths(doc)
    path = paths[int(rng.integers(len(paths)))]
    parent, key = _get(doc, path[:-1]), path[-1]
    op = int(rng.integers(4))
    where = "/".join(map(str, path))
    if op == 0 and isinstance(parent, dict):
        del parent[key]
        return f"delete {where}", doc
    if op == 0 and isinstance(parent, list):
        del parent[key]
        return f"delete {where}", doc
    if op == 1 and isinstance(parent, dict):
        parent[f"extra_{int(rng.integers(100))}"] = ODD_VALUES[int(rng.integers(len(ODD_VALUES)))]
        return f"extra field beside {where}", doc
    value = parent[key]
    if op == 2 and isinstance(value, (int, float)) and not isinstance(value, bool):
        factor = [0.0, -1.0, 10.0, 1e6, 1e-6, math.nan, math.inf][int(rng.integers(7))]
        new = value * factor if math.isfinite(factor) else factor
        parent[key] = new
        return f"{where} *= {factor}", doc
    new = ODD_VALUES[int(rng.integers(len(ODD_VALUES)))]
    parent[key] = new
    return f"{where} = {new!r}", doc


def mutate_bytes(raw: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """One byte-level change: truncation, a flipped byte, a deleted or repeated span."""
    n = len(raw)
    op = int(rng.integers(4))
    if op == 0:
        k = int(rng.integers(n))
        return f"truncated at byte {k} of {n}", raw[:k]
    if op == 1:
        k = int(rng.integers(n))
        b = int(rng.integers(1, 256))
        return f"byte {k} xor {b}", raw[:k] + bytes([raw[k] ^ b]) + raw[k + 1:]
    a = int(rng.integers(n))
    b = min(n, a + int(rng.integers(1, 64)))
    if op == 2:
        return f"bytes {a}..{b} deleted", raw[:a] + raw[b:]
    return f"bytes {a}..{b} repeated", raw[:b] + raw[a:b] + raw[b:]


def json_mutations(raw: bytes, seed: int, n: int, under: tuple[str, ...] = ()) -> Iterator[tuple[str, bytes]]:
    """``n`` mutations of a JSON file: three structured changes to one byte-level change; with
    ``under``, structured changes only, of fields below those top-level keys (the fields a
    loader passes on to the commands: a model's provenance, its fit report)."""
    doc = json.loads(raw)
    rng = np.random.default_rng(seed)
    for i in range(n):
        if i % 4 == 3 and not under:
            yield mutate_bytes(raw, rng)
        else:
            label, new = mutate_document(doc, rng, under)
            yield label, json.dumps(new, indent=2).encode()  # NaN and Infinity written as Python writes them


def toml_mutations(raw: bytes, seed: int, n: int) -> Iterator[tuple[str, bytes]]:
    """``n`` mutations of a TOML file (structured changes written back with tomli-w)."""
    import tomli_w

    doc = tomllib.loads(raw.decode())
    rng = np.random.default_rng(seed)
    for i in range(n):
        if i % 4 == 3:
            yield mutate_bytes(raw, rng)
            continue
        label, new = mutate_document(doc, rng)
        try:
            text = tomli_w.dumps(_toml_safe(new))
        except (TypeError, ValueError):  # a value TOML cannot hold (None): the field is left out instead
            text = tomli_w.dumps(_toml_safe(new, drop_none=True))
        yield label, text.encode()


def _toml_safe(node, drop_none: bool = True):
    if isinstance(node, dict):
        return {k: _toml_safe(v) for k, v in node.items() if not (drop_none and v is None)}
    if isinstance(node, list):
        return [_toml_safe(v) for v in node if v is not None]
    if isinstance(node, int) and not isinstance(node, bool) and abs(node) >= 2**63:
        return float(node)
    return node


def mutate_frame(table, rng: np.random.Generator):
    """One change of a table: a cell, a column (dropped, renamed, all NaN/inf/0, text), rows
    (cut, shuffled, repeated); ``(label, frame)``, or ``(None, None)`` for a byte-level change."""
    import pandas as pd

    cells = ["", "nan", "inf", "-inf", "x", "1e308", "-1e308", "0", "1,5", "--"]
    op = int(rng.integers(9))
    t = table.copy()
    col = t.columns[int(rng.integers(len(t.columns)))]
    if op == 0:
        r = int(rng.integers(len(t)))
        v = cells[int(rng.integers(len(cells)))]
        t[col] = t[col].astype(object)
        t.iloc[r, t.columns.get_loc(col)] = v
        return f"row {r} {col!r} = {v!r}", t
    if op == 1:
        return f"column {col!r} dropped", t.drop(columns=[col])
    if op == 2:
        return f"column {col!r} renamed", t.rename(columns={col: f"{col}_renamed"})
    if op == 3:
        k = int(rng.integers(len(t)))
        return f"first {k} rows kept", t.iloc[:k]
    if op == 4:
        return "rows shuffled", t.sample(frac=1.0, random_state=int(rng.integers(2**31)))
    if op == 5:
        v = [math.nan, math.inf, 0.0, 1e308, -1e308][int(rng.integers(5))]
        t[col] = v
        return f"column {col!r} all {v}", t
    if op == 6:
        r = int(rng.integers(len(t)))
        return f"row {r} repeated", pd.concat([t.iloc[:r + 1], t.iloc[r:]])
    if op == 7:
        t[col] = t[col].astype(str)
        return f"column {col!r} as text", t
    return None, None


def csv_mutations(raw: bytes, seed: int, n: int) -> Iterator[tuple[str, bytes]]:
    """``n`` mutations of a CSV table: cells, columns, rows, headers, bytes."""
    import pandas as pd

    table = pd.read_csv(io.BytesIO(raw))
    rng = np.random.default_rng(seed)
    for _ in range(n):
        label, t = mutate_frame(table, rng)
        yield mutate_bytes(raw, rng) if t is None else (label, t.to_csv(index=False).encode())


def parquet_mutations(raw: bytes, seed: int, n: int) -> Iterator[tuple[str, bytes]]:
    """``n`` mutations of a Parquet table (written back with pyarrow), or of its bytes."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pq.read_table(io.BytesIO(raw))
    frame = table.to_pandas()
    rng = np.random.default_rng(seed)
    for _ in range(n):
        label, t = mutate_frame(frame, rng)
        if t is None:
            yield mutate_bytes(raw, rng)
            continue
        t = pd.DataFrame(t)
        for c in t.columns[t.dtypes == object]:  # a column with one text cell is a text column in Parquet
            t[c] = t[c].astype(str)
        buf = io.BytesIO()
        out = pa.Table.from_pandas(t, preserve_index=False)
        pq.write_table(out.replace_schema_metadata({**(table.schema.metadata or {}), **(out.schema.metadata or {})}), buf)
        yield label, buf.getvalue()


def written(tmp_path: Path, name: str, gen, raw: bytes, seed: int, n: int):
    """Mutations of ``raw`` written one after another to ``tmp_path/name``: ``(path, label)``."""
    path = tmp_path / name
    for i, (label, content) in enumerate(gen(raw, seed, n)):
        path.write_bytes(content)
        yield path, f"#{i} {label}"

"""Draw the README's picture from a `make demo` run: the validation error falling round by round.

Usage: python scripts/docs_figure.py [DEMO_DIR] [OUT_PNG]   (defaults: demo-out, docs/assets/loop-error.png)

Reads the `validate --json-out` files `scripts/demo.sh` writes (validate-<model>.json), one per
round, and plots each model's validation RMSE (on runs no fit saw) with its 95 % interval.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(demo_dir: Path, out_png: Path) -> None:
    files = sorted(demo_dir.glob("validate-*.json"), key=lambda p: len(p.name))
    if not files:
        sys.exit(f"error: no validate-*.json in {demo_dir}: run `make demo` (or scripts/demo.sh {demo_dir}) first")
    rounds = [json.loads(p.read_text()) for p in files]
    labels, rmse, lo, hi = [], [], [], []
    previous: set[str] = set()
    for r in rounds:
        effects = set(r["model"]["effects"])
        added = sorted(effects - previous)
        labels.append("the paper's modified PI\n(pi + envelope)" if not previous else "+ " + ", ".join(added))
        previous = effects
        m = r["metrics"]["rmse_deg"]
        rmse.append(m["value"] if isinstance(m, dict) else m)
        ci = r["metrics"].get("ci", {}).get("rmse_deg")
        lo.append(ci[0] if ci else rmse[-1])
        hi.append(ci[1] if ci else rmse[-1])
    fig, ax = plt.subplots(figsize=(7.0, 3.0), dpi=100)
    x = range(len(rmse))
    ax.bar(x, rmse, color=["#9e9e9e"] + ["#3f51b5"] * (len(rmse) - 1), width=0.6)
    ax.errorbar(x, rmse, yerr=[[v - a for v, a in zip(rmse, lo)], [b - v for v, b in zip(rmse, hi)]],
                fmt="none", ecolor="black", capsize=3, lw=1)
    for i, (v, top) in enumerate(zip(rmse, hi)):
        ax.text(i, top + 0.03, f"{v:.2f}°", ha="center", va="bottom", fontsize=10)
    ax.set_xticks(list(x), labels, fontsize=9)
    ax.set_ylabel("validation RMSE (deg)")
    ax.set_ylim(0, max(hi) * 1.25)
    ax.set_title("validate names the missing effect; each refit lowers the error on runs no fit saw", fontsize=10)
    ax.spines[["top", "right"]].set_visible(False)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png)
    print(f"wrote {out_png}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(Path(args[0]) if args else Path("demo-out"), Path(args[1]) if len(args) > 1 else Path("docs/assets/loop-error.png"))

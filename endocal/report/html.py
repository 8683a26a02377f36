"""The report as one self-contained HTML page.

Figures are embedded as base64 PNG ``data:`` URIs and the style sheet is inline, so the file
opens offline, can be mailed as is, and prints cleanly (a print style sheet drops the
navigation, keeps figures and table rows whole and starts major sections on a new page).
Everything on the page is rendered from the :class:`~endocal.report.result.Report`.
"""

from __future__ import annotations

import base64
import math
from html import escape

from endocal.report.stats import stars
from endocal.validation.metrics import METRIC_KEYS

CSS = """
:root { --ink:#1d2330; --muted:#5b6476; --line:#d9dde5; --accent:#1f5fa8; --good:#1d7a3a; --warn:#a8561f; --bg:#fff; }
* { box-sizing: border-box; }
body { font: 14px/1.5 -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; color: var(--ink); background: var(--bg);
       margin: 0; }
main { max-width: 1180px; margin: 0 auto; padding: 24px 32px 64px; }
header.top { border-bottom: 3px solid var(--accent); margin-bottom: 16px; }
h1 { font-size: 26px; margin: 8px 0 4px; }
h2 { font-size: 20px; margin: 36px 0 10px; padding-bottom: 4px; border-bottom: 1px solid var(--line); }
h3 { font-size: 16px; margin: 24px 0 8px; }
p.sub, .muted { color: var(--muted); }
nav { font-size: 13px; margin: 8px 0 16px; }
nav a { color: var(--accent); margin-right: 14px; text-decoration: none; }
ul.findings { padding-left: 0; list-style: none; }
ul.findings li { margin: 6px 0; padding: 8px 12px; border-left: 4px solid var(--line); background: #f6f8fb; }
ul.findings li.sig { border-left-color: var(--good); }
ul.findings li.ns { border-left-color: #b9c0cc; }
.badge { display: inline-block; font-size: 11px; padding: 1px 6px; border-radius: 8px; margin-left: 6px; vertical-align: 1px; }
.badge.sig { background: #dcefe1; color: var(--good); }
.badge.ns { background: #eceef2; color: var(--muted); }
.warn { border-left: 4px solid var(--warn); background: #fbf3ec; padding: 8px 12px; margin: 8px 0; }
table { border-collapse: collapse; width: 100%; font-size: 12.5px; margin: 8px 0 16px; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 8px; text-align: right; vertical-align: top; }
th { background: #f1f3f7; font-weight: 600; }
td.l, th.l { text-align: left; }
tr.best td { font-weight: 600; }
td .ci { color: var(--muted); font-weight: 400; font-size: 11px; display: block; }
figure { margin: 12px 0 24px; break-inside: avoid; page-break-inside: avoid; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { color: var(--muted); font-size: 12.5px; margin-top: 4px; }
code, .eq { font-family: "SFMono-Regular", Menlo, Consolas, monospace; font-size: 12px; }
.eq { background: #f6f8fb; padding: 6px 10px; display: block; white-space: pre-wrap; word-break: break-word; }
.grid2 { display: grid; grid-template-columns: 1fr 1fr; gap: 16px; }
@media (max-width: 900px) { .grid2 { grid-template-columns: 1fr; } }
@media print {
  @page { size: A4; margin: 14mm; }
  body { font-size: 10.5pt; }
  main { max-width: none; padding: 0; }
  nav { display: none; }
  h2 { break-before: page; page-break-before: always; }
  h2.first { break-before: auto; page-break-before: auto; }
  tr, figure, ul.findings li { break-inside: avoid; page-break-inside: avoid; }
  figure img { border: none; max-height: 230mm; }
  .grid2 { grid-template-columns: 1fr; }
  a { color: inherit; text-decoration: none; }
}
"""


def _f(x, nd: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "&ndash;"
    return f"{x:.{nd}f}"


def _p(p) -> str:
    if p is None or not math.isfinite(p):
        return "&ndash;"
    return f"{p:.2g}" if p >= 1e-4 else "&lt; 0.0001"


def _pct(x) -> str:
    return "&ndash;" if x is None else f"{x:+.1f} %"


def _img(fig) -> str:
    b64 = base64.b64encode(fig.png).decode("ascii")
    return (f'<figure id="{escape(fig.id)}"><img alt="{escape(fig.title)}" src="data:image/png;base64,{b64}">'
            f"<figcaption><b>{escape(fig.title)}.</b> {escape(fig.caption)}</figcaption></figure>")


_LABELS = {"rmse_deg": "RMSE (deg)", "mae_deg": "MAE (deg)", "max_deg": "max (deg)", "median_deg": "median (deg)",
           "median_pct": "median (%)"}


def _metrics_table(report) -> str:
    rows = []
    for r in report.metrics_rows():
        cells = "".join(
            f'<td>{_f(r[k])}<span class="ci">{_f(r[k + "_ci_low"])} &ndash; {_f(r[k + "_ci_high"])}</span></td>'
            for k in METRIC_KEYS)
        rows.append(
            f'<tr class="{"best" if r["best"] else ""}"><td class="l">{escape(r["data"])}</td>'
            f'<td class="l">{escape(r["signal"])}</td><td class="l">{escape(r["axis"])}</td>'
            f'<td class="l">{escape(r["model"])}{" &#9733;" if r["best"] else ""}</td>{cells}'
            f'<td>{r["n"]}</td><td class="l">{"in-sample" if r["in_sample"] else "held-out"}</td></tr>')
    head = "".join(f"<th>{_LABELS[k]}<br><span class='muted'>95 % CI</span></th>" for k in METRIC_KEYS)
    return (f'<table><thead><tr><th class="l">record</th><th class="l">signal</th><th class="l">axis</th>'
            f'<th class="l">model</th>{head}<th>samples</th><th class="l">fitted on it?</th></tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table>')


def _tests(group) -> str:
    c = group.comparison
    out = [f"<h3>{escape(group.data)}, axis {escape(group.axis)}</h3>", f"<p>{escape(c.why)}</p>"]
    if c.test == "none":
        return "".join(out)
    if c.test == "friedman":
        out.append(f"<p>Friedman &chi;&sup2; = {_f(c.statistic, 2)}, p = {_p(c.p_value)}, Kendall's W = "
                   f"{_f(c.effect_size, 2)} ({'models differ' if c.significant else 'no difference shown'}).</p>")
    rows = "".join(
        f'<tr><td class="l">{escape(p.a)}</td><td class="l">{escape(p.b)}</td><td>{p.n}</td><td>{_f(p.statistic, 1)}</td>'
        f'<td>{_p(p.p_value)}</td><td>{_p(p.p_adjusted)}</td><td>{stars(p.p_adjusted)}</td>'
        f'<td>{_f(p.rank_biserial, 2)}</td><td>{_f(p.median_diff_deg)}</td>'
        f'<td class="l">{escape(p.better or "tie") if p.significant(c.alpha) else "&ndash;"}</td></tr>' for p in c.pairs)
    out.append('<table><thead><tr><th class="l">model a</th><th class="l">model b</th><th>pairs</th>'
               "<th>Wilcoxon T</th><th>p</th><th>p (Holm)</th><th></th><th>rank-biserial r</th>"
               '<th>median a&minus;b (deg)</th><th class="l">better</th></tr></thead>'
               f"<tbody>{rows}</tbody></table>")
    return "".join(out)


def _ladder_table(report) -> str:
    if not report.ladder:
        return ""
    rows = []
    for s in report.ladder:
        ci = s["heldout_ci"]
        held = ("<td>&ndash;</td>" if s["heldout_rmse_deg"] is None else
                f'<td>{_f(s["heldout_rmse_deg"])}<span class="ci">{_f(ci[0]) if ci else "&ndash;"} &ndash; '
                f'{_f(ci[1]) if ci else "&ndash;"}</span></td>')
        why = "" if s["heldout_error"] is None else f'<span class="ci">{escape(s["heldout_error"])}</span>'
        test = ("&ndash;" if s["p_adjusted"] is None else f'{_p(s["p_adjusted"])} {stars(s["p_adjusted"])}')
        rows.append(
            f'<tr><td class="l">{escape(s["axis"])}</td><td class="l">{escape(s["data"])}</td>'
            f'<td class="l">{escape(s["step"])}{why}</td><td>{s["n_effects"]}</td>'
            f'<td class="l">{escape(s.get("scheme") or "-")}</td><td>{_f(s["train_rmse_deg"])}</td>'
            f'{held}<td>{_pct(s["change_pct"])}</td><td>{test}</td><td>{_f(s["file_rmse_deg"])}</td>'
            f'<td class="l">{"in-sample" if s["file_fitted_on_record"] else "held-out"}</td></tr>')
    return ('<table><thead><tr><th class="l">axis</th><th class="l">record</th><th class="l">model</th><th>effects</th>'
            '<th class="l">scheme</th><th>in-sample RMSE (deg)<br><span class="muted">the fits, on their training data</span></th>'
            '<th>held-out RMSE (deg)<br><span class="muted">95 % CI</span></th><th>held-out change vs previous step</th>'
            '<th>p (one-sided, Holm)</th><th>model file RMSE (deg)</th><th class="l">model file fitted on record?</th>'
            f'</tr></thead><tbody>{"".join(rows)}</tbody></table>')


def _models(report) -> str:
    figs = {f.group: f for f in report.figures if f.section == "models"}
    out = []
    for m in report.models:
        fit = m.model.fit_report_
        fit_txt = ("parameters set by hand (no fit)" if fit is None else
                   f"fit: {fit.n_samples} samples in {fit.n_runs} run(s), {fit.n_free} free parameters, "
                   f"{fit.nfev} evaluations, RMSE {fit.rmse_deg:.3f} deg, {'converged' if fit.success else 'NOT converged'}"
                   f" ({fit.message}){'; rank deficient: some parameters are not identified' if fit.rank_deficient else ''}")
        out.append(f"<h3>{escape(m.label)} <span class='muted'>({escape(m.axis)}, {escape(m.name)})</span></h3>"
                   f"<code class='eq'>{escape(m.model.equation())}</code><p class='muted'>{escape(fit_txt)}</p>")
        if m.label in figs:
            out.append(_img(figs[m.label]))
    return "".join(out)


def _provenance(report) -> str:
    p = report.provenance
    rows = [("endocal", p.get("endocal_version")), ("created (UTC)", p.get("created_utc")),
            ("command", p.get("command") or "(library call)"),
            ("bootstrap", f"{p['bootstrap']['n_boot']} replicates, seed {p['bootstrap']['seed']}, moving blocks"),
            ("software", ", ".join(f"{k} {v}" for k, v in (p.get("software") or {}).items()))]
    body = "".join(f'<tr><th class="l">{escape(k)}</th><td class="l">{escape(str(v))}</td></tr>' for k, v in rows)
    mrows = "".join(
        f'<tr><td class="l">{escape(m["label"])}</td><td class="l">{escape(str(m["path"]))}</td>'
        f'<td class="l"><code>{escape(str(m["sha256"]))}</code></td><td class="l">{escape(m["axis"])}</td></tr>'
        for m in p["models"])
    drows = "".join(
        f'<tr><td class="l">{escape(d["label"])}</td><td class="l">{escape(d["path"])}</td>'
        f'<td class="l"><code>{escape(d["sha256"])}</code></td><td class="l">{escape(str(d["protocol"]))}</td>'
        f'<td>{escape(str(d["seed"]))}</td><td class="l">{escape(str(d["backend"]))}</td>'
        f'<td class="l">{escape(str(d["started_utc"]))}</td></tr>' for d in p["data"])
    planes = ""
    if p.get("planes"):
        planes = (f"<p>Bending planes: {escape(str(p['planes']['path']))} <code>{escape(str(p['planes']['sha256']))}"
                  "</code></p>")
    return (f"<table>{body}</table><h3>Model files</h3><table><thead><tr><th class='l'>model</th><th class='l'>file</th>"
            f"<th class='l'>SHA-256</th><th class='l'>axis</th></tr></thead><tbody>{mrows}</tbody></table>"
            "<h3>Data</h3><table><thead><tr><th class='l'>record</th><th class='l'>path</th><th class='l'>SHA-256</th>"
            "<th class='l'>protocol</th><th>seed</th><th class='l'>backend</th><th class='l'>recorded (UTC)</th></tr>"
            f"</thead><tbody>{drows}</tbody></table>{planes}")


def render_html(report) -> str:
    """The full HTML page of a :class:`~endocal.report.result.Report`."""
    findings = []
    for f in report.findings:
        cls = "sig" if f.significant else "ns"
        badge = ("significant" if f.significant else "not significant" if f.significant is False else "untested")
        findings.append(f'<li class="{cls}">{escape(f.sentence)}<span class="badge {cls}">{badge}</span></li>')
    skipped = "".join(f'<div class="warn"><b>Not evaluated:</b> {escape(n.model)} on {escape(n.data)} '
                      f"({escape(n.axis)}): {escape(n.reason)}</div>" for n in report.not_evaluated)
    notes = "".join(f'<div class="warn">{escape(n)}</div>'
                    for n in [x for g in report.groups for e in g.evaluations for x in e.notes] + list(report.notes))
    wins: dict[str, int] = {}
    for f in report.findings:
        wins[f.best] = wins.get(f.best, 0) + 1
    tally = ", ".join(f"{escape(m)} on {k} of {len(report.findings)}" for m, k in sorted(wins.items(), key=lambda x: -x[1]))

    record_sections = []
    for g in report.groups:
        key = f"{g.data}/{g.axis}"
        figs = [f for f in report.figures if f.group == key]
        record_sections.append(f"<h3 id='rec-{escape(g.data)}-{escape(g.axis)}'>{escape(g.data)} "
                               f"({escape(g.finding.signal)}), axis {escape(g.axis)}</h3>"
                               f"<p>{escape(g.finding.sentence)}</p>" + "".join(_img(f) for f in figs))
    ladder_figs = "".join(_img(f) for f in report.figures if f.section == "ladder")
    planes = "".join(_img(f) for f in report.figures if f.section == "planes")
    task = "".join(_img(f) for f in report.figures if f.section == "task-space")
    checks = "".join(_img(f) for f in report.figures if f.section == "checks")
    nav = ["summary", "metrics", "tests", "records", "ladder", "models"]
    if planes:
        nav.append("planes")
    if task:
        nav.append("task-space")
    if checks:
        nav.append("checks")
    nav.append("provenance")
    p = report.provenance
    sections = [
        f'<h2 id="summary" class="first">Summary</h2><p>Best model by RMSE: {tally}.</p>'
        f'<ul class="findings">{"".join(findings)}</ul>{skipped}{notes}',
        '<h2 id="metrics">Metrics</h2><p class="muted">Error = predicted &minus; measured bending angle, per model, '
        "record and axis; 95 % confidence intervals from a moving-block bootstrap (blocks as long as the error's "
        "autocorrelation, so intervals are not too narrow). Median % is relative to the measured half range. "
        "&#9733; marks the lowest RMSE of each record.</p>" + _metrics_table(report),
        '<h2 id="tests">Statistical tests</h2><p class="muted">Samples of a tracking error are autocorrelated, so '
        "models are compared on per-unit errors (one unit per branch of the hysteresis loop, or per decorrelation-"
        "length block), paired across models: Wilcoxon signed-rank for two models, Friedman with Holm-corrected "
        "pairwise Wilcoxon tests for more. Significance level 0.05.</p>" + "".join(_tests(g) for g in report.groups),
        '<h2 id="records">Records</h2>' + "".join(record_sections),
        '<h2 id="ladder">Model ladder</h2><p class="muted">Does adding an effect pay? Each step adds effects to a '
        "base model. Every step's structure (base and effects, with its model file's settings) is scored as "
        "<code>endocal validate</code> scores it: when the model file names other records as its training data, "
        "refitted on them (estimation data) and run over the whole record (validation data, never seen); otherwise "
        "by blocked rolling-origin cross-validation on the record: fitted on the first half and on every later "
        "origin, scored on the next block it has not seen. The scheme column says which. In-sample error falls with every "
        "parameter added; the held-out error falls only when the effect is real. The p-value tests the step's held-out "
        "gain over the previous step (one-sided paired test on block-mean loss differentials, Wilcoxon signed-rank, "
        "Holm-corrected over the steps of a record). The last columns give the model file as it was fitted.</p>"
        + (ladder_figs or "<p>Only one model per axis: no ladder to draw.</p>") + _ladder_table(report),
        '<h2 id="models">Models</h2>' + _models(report),
    ]
    if planes:
        pnotes = "".join(f'<div class="warn">{escape(n)}</div>' for n in
                         (report.planes_view.notes if report.planes_view is not None else []))
        sections.append('<h2 id="planes">Bending planes</h2>' + pnotes + planes)
    if task:
        sections.append('<h2 id="task-space">Task space</h2>' + task)
    if checks:
        sections.append('<h2 id="checks">Probe checks</h2><p class="muted">Is the probe still within its calibration? '
                        "Its checks since calibration (<code>endocal check</code>), charted as radiotherapy QA charts "
                        "its machines (Pawlicki et al., Med Phys 2005).</p>" + checks)
    sections.append('<h2 id="provenance">Provenance</h2>' + _provenance(report))
    nav_links = "".join(f'<a href="#{n}">{n}</a>' for n in nav)
    title = "endocal report: " + ", ".join(dict.fromkeys(m.label for m in report.models))
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{escape(title)}</title><style>{CSS}</style></head><body><main>"
        f"<header class='top'><h1>Hysteresis model report</h1><p class='sub'>{len(report.models)} model(s) on "
        f"{len(report.datas)} record(s) &middot; endocal {escape(str(p.get('endocal_version')))} &middot; "
        f"{escape(str(p.get('created_utc')))}</p></header>"
        f"<nav>{nav_links}</nav>"
        + "".join(sections) + "</main></body></html>"
    )

"""The campaign report as one self-contained HTML page: figures embedded (and linked to their PNG/SVG files),
the stiffness table, impact statistics, and the protocol, rig and world the campaign ran with."""

from __future__ import annotations

import base64
import html
import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from labctl import __version__
from labctl.physics.references import fit_for_rail, model_curve
from labctl.physics.world import world_path
from labctl.report.data import ReportData, SeriesData
from labctl.report.figures import is_simulated
from labctl.report.verdict import COVERAGE, FAIL, PASS, StepVerdict, rig_parameters, steel_fit_applies

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
h1 { font-size: 1.5em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; margin-top: 2em; }
table { border-collapse: collapse; margin: .5em 0 1em; font-size: .9em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; } th { background: #f3f3f3; }
td.l, th.l { text-align: left; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: .9em; color: #444; }
pre { background: #f7f7f7; border: 1px solid #ddd; padding: .8em; overflow-x: auto; font-size: .85em; }
.bad { color: #a00; } .ok { color: #070; } .undecided { color: #a60; }
.sim { background: #b00000; color: #fff; padding: .5em 1em; font-weight: bold; font-size: 1.2em; }
dl.glossary { font-size: .85em; color: #333; } dl.glossary dt { font-weight: bold; float: left; clear: left;
  margin-right: .5em; } dl.glossary dd { margin: 0 0 .2em 0; }
tr.drift td { background: #fff4e0; }
@page { margin: 15mm 12mm; }  /* no size: the printer's paper, A4 or Letter; content fits the narrower */
@media print {
  body { margin: 0; max-width: none; font-size: 10pt; }
  h2, h3 { break-after: avoid; page-break-after: avoid; }
  table, figure, pre { break-inside: avoid; page-break-inside: avoid; }
  table.long { break-inside: auto; page-break-inside: auto; }
  thead { display: table-header-group; } tr { break-inside: avoid; page-break-inside: avoid; }
  figure img { max-width: 100%; max-height: 220mm; }
  pre { white-space: pre-wrap; font-size: 8pt; }
  .sim { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  a { color: inherit; text-decoration: none; }
}
"""

GLOSSARY = {
    "stiffness": [
        ("step", "the load step's number in the protocol (the same in every repetition)"),
        ("load [N]", "the mean load per roller over the repetitions, read by the load cell before the blows"),
        ("k mean [N/µm]", "the mean measured roller contact stiffness over the repetitions (Eq. 4 from the "
                          "bounce frequency)"),
        ("spread", "(largest − smallest) / mean of the repetitions' stiffness at this step"),
        ("repetitions", "how many repetitions identified this step"),
        ("Tripp, Eq. 5/6, Hertz [N/µm]", "the model's stiffness at the mean load"),
        ("k/model − 1", "the relative difference of the measured mean from the reference model; '–' where "
                        "the model does not apply (no verdict)"),
    ],
    "verdict": [
        ("k ± u [N/µm]", "the mean stiffness and u, its standard uncertainty (scatter over the repetitions and "
                         "the rig's systematic part)"),
        ("band", "how far from the model a step may be and still pass"),
        ("verdict", "pass / fail / cannot tell by the rule above; no verdict where the model does not apply"),
        ("note", "why a verdict is limited: a drifted load, one repetition, a model that does not apply"),
    ],
}


def _glossary(which: str) -> str:
    return ("<dl class=glossary>" + "".join(f"<dt>{_e(term)}</dt><dd>{_e(text)}</dd>"
                                            for term, text in GLOSSARY[which]) + "</dl>")



def _e(value: Any) -> str:
    return html.escape(str(value))


def _table(head: list[str], rows: list[list[Any]], left: int = 0) -> str:
    def cell(tag: str, i: int, v: Any) -> str:
        return f"<{tag}{' class=l' if i < left else ''}>{_e(v)}</{tag}>"

    out = [f"<table{' class=long' if len(rows) > 15 else ''}><thead><tr>"
           + "".join(cell("th", i, h) for i, h in enumerate(head)) + "</tr></thead><tbody>"]
    out += ["<tr>" + "".join(cell("td", i, v) for i, v in enumerate(r)) + "</tr>" for r in rows]
    return "\n".join(out) + "</tbody></table>"


def _figure(name: str, title: str, png: Path, svg: Path) -> str:
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    return (f'<figure id="{_e(name)}"><a href="{_e(svg.name)}"><img alt="{_e(title)}" '
            f'src="data:image/png;base64,{data}"></a><figcaption>{_e(title)} — '
            f'<a href="{_e(png.name)}">{_e(png.name)}</a> · <a href="{_e(svg.name)}">{_e(svg.name)}</a>'
            "</figcaption></figure>")


def _stiffness_table(s: SeriesData) -> str:
    stats = s.step_stats()
    loads = np.array([st.load_n for st in stats])
    ref = "hertz" if s.kind == "ball" else fit_for_rail(s.case.rail_ra_m)
    applies = s.kind == "ball" or steel_fit_applies(s)[0]  # what the verdict disowns is not printed
    ref_k = model_curve(ref, s.case, loads) if applies else np.full(len(loads), np.nan)
    tripp = model_curve("tripp", s.case, loads) if s.kind != "ball" else np.full(len(loads), np.nan)
    ref_name = {"hertz": "Hertz", "fit-ra0.2": "Eq. 5", "fit-ra0.03": "Eq. 6"}[ref]
    rows = []
    springs = any(np.isfinite(st.load_std_n) for st in stats)  # loads from the spring curve: show their σ
    for st, k_ref, k_t in zip(stats, ref_k, tripp, strict=True):
        load = f"{st.load_n:.1f}" + (f" ± {st.load_std_n:.1f}" if springs and np.isfinite(st.load_std_n) else "")
        rows.append([st.step, load, f"{st.stiffness_n_per_m * 1e-6:.2f}", f"{st.spread:.2%}",
                     st.repetitions, "–" if not np.isfinite(k_t) else f"{k_t * 1e-6:.2f}",
                     "–" if not np.isfinite(k_ref) else f"{k_ref * 1e-6:.2f}",
                     "–" if not np.isfinite(k_ref) else f"{st.stiffness_n_per_m / k_ref - 1:+.2%}"])
    load_head = "load ± 1-σ (spring curve) [N]" if springs else "load [N]"
    head = ["step", load_head, "k mean [N/µm]", "spread", "repetitions", "Tripp [N/µm]", f"{ref_name} [N/µm]",
            f"k/{ref_name} − 1"]
    return f"<h3>{_e(s.name)}</h3>" + _table(head, rows)


def _verdict_rows(verdicts: list[StepVerdict]) -> list[str]:
    css = {PASS: "ok", FAIL: "bad"}
    rows = []
    for v in verdicts:
        dev = "–" if not np.isfinite(v.deviation) else f"{v.deviation:+.1%}"
        model = "–" if not np.isfinite(v.model_n_per_m) else f"{v.model_n_per_m * 1e-6:.2f}"
        cells = [v.label, v.step, f"{v.load_n:.1f}", f"{v.stiffness_n_per_m * 1e-6:.2f} ± {v.std_n_per_m * 1e-6:.2f}",
                 v.repetitions, f"{v.model or '–'} {model}", f"±{v.band:.0%}", dev]
        row = "".join(f"<td{' class=l' if i == 0 else ''}>{_e(c)}</td>" for i, c in enumerate(cells))
        row += (f"<td class='l {css.get(v.verdict, 'undecided')}'><b>{_e(v.verdict)}</b></td>"
                f"<td class=l>{_e(v.note)}</td>")
        rows.append(f"<tr{' class=drift' if 'drifted' in v.note else ''}>{row}</tr>")
    return rows


def _verdicts(verdicts: list[StepVerdict], band: float | None) -> str:
    if not verdicts:
        return "<p>No identified step to judge.</p>"
    counts = {k: sum(v.verdict == k for v in verdicts) for k in dict.fromkeys(v.verdict for v in verdicts)}
    rule = (f"<p>Rule: each step's mean stiffness over its repetitions against the reference model at the mean "
            f"load (rollers: Eq. 5 for rails Ra ≥ 0.1 µm, else Eq. 6; balls: Hertz). u combines the standard error "
            f"of the mean over the repetitions with the rig's systematic uncertainty (disc mass, K_setup, rig model; "
            f"see Rig and model parameters). With k ± {COVERAGE:g}u (about 95 %): <b>pass</b> when the whole "
            f"interval lies within the band, <b>fail</b> when it lies wholly outside, otherwise <b>cannot tell</b>. "
            f"Eqs. 5/6 were fitted to steel rollers: rollers whose contact modulus E* differs from bearing "
            f"steel's by more than 5 % get no verdict. Band: ±{(band if band is not None else 0.10):.0%} for "
            f"rollers" + ("" if band is not None else ", ±5 % for balls") + ".</p>")
    head = ["specimen", "step", "load [N]", "k ± u [N/µm]", "repetitions", "model [N/µm]", "band", "k/model − 1",
            "verdict", "note"]
    table = ("<table class=long><thead><tr>" + "".join(f"<th{' class=l' if i in (0, 8, 9) else ''}>{_e(h)}</th>"
                                                   for i, h in enumerate(head)) + "</tr></thead><tbody>\n"
             + "\n".join(_verdict_rows(verdicts)) + "</tbody></table>")
    summary = ", ".join(f"{n} {k}" for k, n in counts.items())
    return f"<p><b>{len(verdicts)} steps: {_e(summary)}.</b></p>" + rule + table + _glossary("verdict")


def _parameters(data: ReportData) -> str:
    rows = [[p.name, p.value, p.std or "–", p.source] for p in rig_parameters(data.rig)]
    return ("<p>Every stiffness is computed from the bounce frequency with these rig parameters (Eq. 4); the "
            "models with these parameters. 1-σ uncertainties as given by the rig file.</p>"
            + _table(["parameter", "value", "1-σ", "from"], rows, left=4))


def _events(data: ReportData) -> str:
    """Run events: every step where something happened that the numbers alone do not say, one line each."""
    rows = [(s.name, e) for s in data.series for e in s.events if e.notes()]
    if not rows:
        return ("<p>Nothing happened outside the plan: no load drift, no channel left out, no operator override, "
                "no identification warning.</p>")
    drifts = sum(e.drifted() for s in data.series for e in s.events)
    overrides = sum(len(e.overrides) for s in data.series for e in s.events)
    head = (f"<p>{len(rows)} steps with events: {drifts} with the load drifting during the step, {overrides} "
            "operator override(s). Load before: read before the blows (the load the stiffness is reported at); "
            "after: read after the step's last blow.</p>")
    cols = ["specimen", "run", "step", "load before [N]", "load after [N]", "what happened"]
    out = ["<table class=long><thead><tr>" + "".join(f"<th{' class=l' if c in (cols[0], cols[-1]) else ''}>"
                                                     f"{_e(c)}</th>" for c in cols) + "</tr></thead><tbody>"]
    for name, e in rows:
        after = "–" if e.load_after_n != e.load_after_n else f"{e.load_after_n:.1f}"
        notes = "<br>".join(_e(n) for n in e.notes())
        out.append(f"<tr{' class=drift' if e.drifted() else ''}><td class=l>{_e(name)}</td><td>{e.run}</td>"
                   f"<td>{e.step}</td><td>{e.load_before_n:.1f}</td><td>{after}</td><td class=l>{notes}</td></tr>")
    return head + "\n".join(out) + "</tbody></table>"


def _impacts(data: ReportData) -> str:
    st = data.impacts
    overrides = [(s.name, e, o) for s in data.series for e in s.events for o in e.overrides]
    against = (f" ({sum(o.accepted for *_, o in overrides)} accepted and {sum(not o.accepted for *_, o in overrides)}"
               " rejected by the operator against the checks)") if overrides else ""
    parts = [f"<p>{st.accepted} impacts accepted, {st.rejected} rejected{against}.</p>"]
    if overrides:
        parts.append(_table(["specimen", "run", "step", "impact", "operator", "checks said", "reason"],
                            [[n, e.run, e.step, o.attempt, "accepted" if o.accepted else "rejected", o.checks,
                              o.reason or "none given"] for n, e, o in overrides], left=1))
    if st.by_reason:
        parts.append(_table(["reason", "impacts"], [[k, v] for k, v in st.by_reason.items()], left=1))
    rejected = [[r.series, r.run, r.step, f"{r.load_n:.1f}", r.accepted, r.rejected, ", ".join(r.reasons)]
                for r in st.rows if r.rejected]
    if rejected:
        parts.append("<p>Steps with rejected impacts:</p>")
        parts.append(_table(["series", "run", "step", "load [N]", "accepted", "rejected", "reasons"], rejected))
    if data.failed_steps:
        parts.append("<p class=bad>Steps that could not be identified:</p>")
        parts.append(_table(["series", "run", "step", "why"], [list(f) for f in data.failed_steps]))
    return "\n".join(parts)


def _world(data: ReportData) -> str:
    if "world.toml" in data.config:
        return f"<pre>{_e(data.config['world.toml'])}</pre>"
    if data.attrs.get("backend") != "sim":
        return f"<p>No simulated world: the data come from backend '{_e(data.attrs.get('backend', '?'))}'.</p>"
    shipped = "balls" if data.series and all(s.kind == "ball" for s in data.series) else None
    path = world_path(shipped)
    return (f"<p>Not stored in the campaign: the simulator's shipped world <code>{_e(path.name)}</code> "
            f"(as shipped with labctl {_e(__version__)}):</p><pre>{_e(path.read_text(encoding='utf-8'))}</pre>")


def _specimens(data: ReportData) -> str:
    rows = []
    for s in data.series:
        r = s.case.roller
        rows.append([s.index, s.name, s.kind, f"{r.diameter_m * 1e3:.3g}", f"{r.contact_length_m * 1e3:.4g}",
                     r.material.name, f"{s.case.rail_ra_m * 1e6:.3g}", s.specimen.conditions_text(), len(s.runs)])
    return _table(["series", "specimen", "kind", "D [mm]", "L_we [mm]", "material", "rail Ra [µm]", "conditions",
                   "repetitions identified"], rows, left=3)


def write_html(data: ReportData, figures: list[tuple[str, str, Path, Path]], out: Path, csv_name: str | None,
               verdicts: list[StepVerdict], band: float | None = None) -> Path:
    """Write ``report.html`` into ``out``; ``figures`` are (name, title, png, svg) of files already written.

    ``verdicts`` are the steps judged with ``band``, the verdict band for rollers (default ±10 %; balls ±5 %),
    see labctl.report.verdict."""
    a = data.attrs
    summary = [["campaign file", str(data.path)], ["protocol", a.get("protocol_name", "")],
               ["status", f"{a.get('status', '')} {a.get('status_message', '')}".strip()],
               ["backend", a.get("backend", "")], ["created", a.get("created_utc", "")],
               ["written by", f"labctl {a.get('software_version', '?')}"],
               ["seed", a.get("seed", "")]]
    description = a.get("backend_description")
    if description:
        summary.append(["backend details", json.dumps(description) if isinstance(description, dict)
                        else description])
    sim = is_simulated(data)
    banner = ["<p class=sim>SIMULATED: these data come from the digital twin (backend 'sim'), not from a "
              "measurement.</p>"] if sim else []
    kind = "simulated" if sim else ("imported" if a.get("backend") == "import" else "measured")
    body = [*banner, f"<h1>Campaign report ({kind}): {_e(a.get('protocol_name', data.path.name))}</h1>",
            _table(["", ""], summary, left=2), "<h2>Specimens</h2>", _specimens(data),
            "<h2>Verdict against the model band</h2>", _verdicts(verdicts, band),
            "<h2>Run events</h2>", _events(data),
            "<h2>Figures</h2>", *([_figure(*f) for f in figures] or ["<p>No identified step to plot.</p>"]),
            "<h2>Stiffness</h2>", *(_stiffness_table(s) for s in data.series if s.runs), _glossary("stiffness")]
    if csv_name:
        body.append(f'<p>Every point: <a href="{_e(csv_name)}">{_e(csv_name)}</a> (stiffness-table CSV).</p>')
    body += ["<h2>Impacts</h2>", _impacts(data), "<h2>Protocol</h2>",
             f"<pre>{_e(data.config['protocol.toml'])}</pre>" if "protocol.toml" in data.config
             else "<p>No protocol stored (imported data).</p>"]
    if "manifest.csv" in data.config:
        body += ["<h2>Import manifest</h2>", f"<pre>{_e(data.config['manifest.csv'])}</pre>"]
    body += ["<h2>Rig</h2>", f"<pre>{_e(data.config.get('rig.toml', 'not stored: the shipped paper rig'))}</pre>",
             "<h2>Rig and model parameters</h2>", _parameters(data), "<h2>World</h2>", _world(data)]
    if "devices.toml" in data.config:
        body += ["<h2>Devices</h2>", f"<pre>{_e(data.config['devices.toml'])}</pre>"]
    now = datetime.now(UTC).isoformat(timespec="seconds")
    body.append(f"<p><small>Report made {now} by labctl {_e(__version__)}.</small></p>")
    page = ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<title>{'SIMULATED — ' if sim else ''}labctl report: {_e(data.path.name)}</title>"
            f"<style>{STYLE}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path

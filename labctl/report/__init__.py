"""Campaign reports: the paper's figures (PNG and SVG) and a self-contained HTML page."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class ReportResult:
    html: str
    csv: str | None
    figures: list[dict[str, str]] = field(default_factory=list)
    impacts: dict[str, Any] = field(default_factory=dict)
    simulated: bool = False
    verdicts: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"html": self.html, "csv": self.csv, "figures": self.figures, "impacts": self.impacts,
                "simulated": self.simulated, "verdicts": self.verdicts}


def build_report(path: str | Path, out: str | Path, frf_step: tuple[int, int, int] | None = None,
                 band: float | None = None) -> ReportResult:
    """Write the figures, the stiffness CSV and ``report.html`` for a campaign file into the folder ``out``.

    ``band``: the verdict band for rollers as a fraction (default 0.10; balls 0.05), labctl.report.verdict."""
    import matplotlib

    matplotlib.use("Agg")  # files only, never a window
    from labctl.report.data import report_data
    from labctl.report.figures import Plot, is_simulated, make_figures, save
    from labctl.report.html import write_html
    from labctl.report.static_figure import compare_methods, static_figure
    from labctl.report.verdict import series_verdicts
    from labctl.stiffness_table import write_stiffness_table
    from labctl.storage import CampaignReader
    from labctl.storage.outputs import output_folder
    from labctl.storage.table import stiffness_points

    with CampaignReader(path) as reader:  # opened and its repetitions read once, for every part of the report
        data = report_data(reader, frf_step)
        methods = compare_methods(reader, data.runs)  # a combined campaign: static against the hammer (§2.5)
        points = stiffness_points(reader, data.runs)
    folder = output_folder("--out", out)
    written = []
    for plot in make_figures(data):
        png, svg = save(plot, folder)
        written.append((plot.name, plot.title, png, svg))
    if methods:
        plot = Plot("fig08_static_vs_hammer", "Static vs hammer stiffness (cf. Fig. 8, §2.5)",
                    static_figure(methods, is_simulated(data)))
        written.append((plot.name, plot.title, *save(plot, folder)))
    csv = folder / "stiffness.csv" if points else None
    if csv is not None:
        write_stiffness_table(csv, points)
    verdicts = [v for s in data.series if s.runs for v in series_verdicts(s, data.rig, band)]
    page = write_html(data, written, folder, csv.name if csv else None, verdicts, band)
    st = data.impacts
    return ReportResult(str(page), str(csv) if csv else None,
                        [{"name": n, "title": t, "png": str(p), "svg": str(s)} for n, t, p, s in written],
                        {"accepted": st.accepted, "rejected": st.rejected, "by_reason": st.by_reason},
                        is_simulated(data),
                        [{"series": v.series, "step": v.step, "load_n": v.load_n,
                          "stiffness_n_per_m": v.stiffness_n_per_m, "std_n_per_m": v.std_n_per_m,
                          "model": v.model, "model_n_per_m": v.model_n_per_m, "band": v.band,
                          "verdict": v.verdict} for v in verdicts])

"""`simbake report OUT.usda` of a wedge stage: the QA of every take in one table.

One row per take, in take order: what it changes, its verdict (clean, its QA warnings, or
FAILED with its one-line error), frames and bake time, and the worst value of each QA
figure (simbake.qa) any take has, marked where it crossed its threshold. Written as a
self-contained HTML page (default OUT.report.html) and printed as text.
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from .errors import SceneError
from .files import check_output_path, write_atomically
from .report import BAD_COLOR, OK_COLOR, format_figure
from .wedge_stage import WedgeStage, read_wedge_stage
from .wedge_takes import TakeResult

FIGURES = ("body_penetration", "cloth_penetration", "cloth_strain", "cloth_self_intersections", "substeps")


def is_wedge(path: str | Path) -> bool:
    """Whether `path` is a wedge stage (read from its layer metadata alone)."""
    from pxr import Sdf, Tf

    path = Path(path)
    if path.suffix.lower() not in (".usda", ".usdc", ".usd") or not path.is_file():
        return False
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path), True)  # metadata only
    except Tf.ErrorException:
        return False
    data = dict(layer.customLayerData).get("simbake", {}) if layer is not None else {}
    return hasattr(data, "get") and bool(data.get("wedge"))


def _qa(take: TakeResult) -> dict[str, Any] | None:
    try:
        return json.loads(take.qa.read_text()) if take.qa is not None else None
    except (OSError, ValueError):
        return None


def _row(take: TakeResult) -> dict[str, Any]:
    """A take's cells: verdict, frames, seconds, and each figure's (text, over its threshold)."""
    if take.error is not None:
        return {"verdict": f"FAILED: {take.error}", "bad": True, "figures": {}}
    qa = _qa(take)
    if qa is None:
        return {"verdict": f"no QA data ({take.qa.name if take.qa else 'none'} is missing)", "bad": True,
                "figures": {}}
    warnings = qa.get("warnings", [])
    summary = qa.get("summary", {})
    figures = {name: (format_figure(name, s["worst"]), s.get("first_over") is not None)
               for name, s in summary.items() if name in FIGURES}
    return {"verdict": "clean" if not warnings else f"{len(warnings)} QA warning(s): " + "; ".join(warnings),
            "bad": bool(warnings), "figures": figures, "frames": len(qa.get("frames", [])),
            "seconds": take.figures.get("wall_seconds", sum(qa.get("figures", {}).get("wall_seconds", [])))}


def _columns(rows: list[dict]) -> list[str]:
    return [name for name in FIGURES if any(name in r["figures"] for r in rows)]


def text_table(wedge: WedgeStage) -> str:
    """The table as plain text, for the terminal."""
    rows = [_row(t) for t in wedge.takes]
    columns = _columns(rows)
    header = ["take", "settings", "frames", "bake s", *columns, "verdict"]
    lines = [header]
    for take, row in zip(wedge.takes, rows):
        cells = [row["figures"].get(c, ("", False)) for c in columns]
        lines.append([take.name, take.label, str(row.get("frames", "")),
                      f"{row['seconds']:.2f}" if "seconds" in row else "",
                      *[text + (" !" if over else "") for text, over in cells], row["verdict"]])
    widths = [max(len(line[k]) for line in lines) for k in range(len(header) - 1)]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(line, widths)) + "  " + line[-1]
                     for line in lines)


def _html(wedge: WedgeStage) -> str:
    e = html.escape
    rows = [_row(t) for t in wedge.takes]
    columns = _columns(rows)
    failed = sum(t.error is not None for t in wedge.takes)
    head = "".join(f"<th>{e(c.replace('_', ' '))}</th>" for c in columns)
    body = []
    for take, row in zip(wedge.takes, rows):
        cells = "".join(f'<td class="{"bad" if over else ""}">{e(text)}</td>'
                        for text, over in (row["figures"].get(c, ("", False)) for c in columns))
        seconds = f"{row['seconds']:.2f}" if "seconds" in row else ""
        default = " (default)" if take.name == wedge.default else ""
        body.append(f'<tr><td>{e(take.name)}{default}</td><td>{e(take.label)}</td><td>{row.get("frames", "")}</td>'
                    f'<td>{seconds}</td>{cells}<td class="{"bad" if row["bad"] else "ok"}">{e(row["verdict"])}</td></tr>')
    summary = (f'<p class="{"bad" if failed else "ok"}">{len(wedge.takes) - failed} of {len(wedge.takes)} '
               f'take(s) baked' + (f", {failed} failed" if failed else "") + "</p>")
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>simbake wedge: {e(wedge.path.name)}</title>
<style>body{{font-family:sans-serif;margin:1.5em;color:#222}} .ok{{color:{OK_COLOR}}}
.bad{{color:{BAD_COLOR};font-weight:bold}} table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;
padding:2px 8px;text-align:left}}</style></head>
<body><h1>{e(wedge.path.name)}: a wedge of {e(wedge.scene)}</h1>{summary}
<p>keys: {e(", ".join(wedge.keys) or "none (seeds only)")}; variant set <code>wedge</code>, default {e(str(wedge.default))}</p>
<table><tr><th>take</th><th>settings</th><th>frames</th><th>bake s</th>{head}<th>verdict</th></tr>
{"".join(body)}</table>
<p>Worst value of each QA figure over the take's frames (simbake.qa); in red where it crossed its threshold.</p>
</body></html>
"""


def write_wedge_report(path: str | Path, output: str | Path | None = None) -> Path:
    """Writes the wedge's table to `output` (.html; default OUT.report.html) and prints it."""
    path = Path(path)
    out = Path(output) if output is not None else path.with_name(path.stem + ".report.html")
    check_output_path(out, (".html",), inputs=[path])
    wedge = read_wedge_stage(path)
    if wedge is None:
        raise SceneError(path, "", "is not a wedge stage")
    page = _html(wedge)
    write_atomically(out, lambda tmp: Path(tmp).write_text(page))
    print(text_table(wedge))
    return out

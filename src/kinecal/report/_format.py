"""Number formats and HTML pieces shared by the reports (one formatter for every table).

Formats
-------
- errors and lengths in mm, times, ratios: 4 significant digits (``num``), e.g.
  ``0.7972``, ``12.35``, ``1105``; scientific notation below 1e-4 and from 1e6;
- an estimate with its standard deviation: the value rounded to the std's second
  significant digit (``pm``), e.g. ``-1105.0294 ± 0.0020``;
- significance (a ratio to a std): one decimal (``ratio``);
- missing values (None, NaN): an em dash.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Iterable, Sequence

from kinecal._version import __version__

__all__ = [
    "details",
    "e",
    "figure",
    "num",
    "page",
    "page_parts",
    "pm",
    "ratio",
    "table",
]

DASH = "—"


def e(x: object) -> str:
    """HTML-escaped text: ``html.escape`` (the html package is not imported for it: its
    table of entities costs 1-2 ms at start-up)."""
    s = str(x).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return s.replace('"', "&quot;").replace("'", "&#x27;")


def _finite(v: object) -> float | None:
    if v is None:
        return None
    try:
        f = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def num(v: object, sig: int = 4) -> str:
    """``v`` with ``sig`` significant digits (trailing zeros kept: columns line up)."""
    f = _finite(v)
    if f is None:
        return DASH
    if f == 0.0:
        return "0"
    exp = math.floor(math.log10(abs(float(f"{f:.{sig - 1}e}"))))  # after rounding
    if exp < -4 or exp >= 6:
        return f"{f:.{sig - 1}e}"
    return f"{f:.{max(sig - 1 - exp, 0)}f}"


def pm(v: object, sd: object, sig: int = 6) -> str:
    """``value ± std``, the value rounded to the std's second significant digit; without
    a std, the value with ``sig`` significant digits."""
    f, s = _finite(v), _finite(sd)
    if f is None:
        return DASH
    if s is None or s <= 0.0:
        return num(f, sig)
    decimals = min(max(1 - math.floor(math.log10(s)), 0), 12)
    if abs(f) >= 1e6 or (f != 0 and abs(f) < 1e-4 and decimals > 8):
        return f"{num(f, 3)} ± {num(s, 2)}"
    return f"{f:.{decimals}f} ± {s:.{decimals}f}"


def ratio(v: object) -> str:
    """A significance (value / std): one decimal."""
    f = _finite(v)
    return DASH if f is None else f"{f:.1f}"


def table(
    head: Sequence[str],
    rows: Iterable[Sequence[str]],
    left: int = 1,
    cls: Sequence[str] = (),
) -> str:
    """An HTML table; cells are HTML already (escape text with :func:`e`), the first
    ``left`` columns left-aligned; ``cls``: a CSS class per row (optional)."""
    th = "".join(
        f"<th{' class=l' if i < left else ''}>{e(h)}</th>" for i, h in enumerate(head)
    )
    body = []
    for k, r in enumerate(rows):
        c = cls[k] if k < len(cls) and cls[k] else ""
        tds = "".join(
            f"<td{' class=l' if i < left else ''}>{x}</td>" for i, x in enumerate(r)
        )
        body.append(f"<tr class={c}>{tds}</tr>" if c else f"<tr>{tds}</tr>")
    return f"<table><tr>{th}</tr>{''.join(body)}</table>"


def details(summary: str, inner: str, *, open_: bool = False) -> str:
    """A collapsible block (``summary`` is HTML)."""
    return f"<details{' open' if open_ else ''}><summary>{summary}</summary>{inner}</details>"


_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;
max-width:1100px;color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}
h2{font-size:1.2em;border-bottom:1px solid #ddd;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:right;white-space:nowrap}
th{background:#f3f3f3}td.l,th.l{text-align:left;white-space:normal}
tr.sig td{background:#fff4e0}tr.fixed td{color:#777}
.box{background:#f6f8fa;border:1px solid #d0d7de;padding:.8em 1.2em;border-radius:6px}
.warn{color:#9a6700}.bad{color:#b00}.muted{color:#666;font-size:.85em}
details{margin:.3em 0}summary{cursor:pointer}
figure{margin:1.2em 0}figure svg{width:100%;max-width:980px;height:auto;
border:1px solid #eee}
nav.toc{font-size:.9em}nav.toc ol{columns:2;margin:.3em 0}
a.csv{font-size:.8em;margin-left:.5em}
@media print{body{max-width:none;margin:0;font-size:10pt}nav.toc,a.csv{display:none}
h2,h3{break-after:avoid}table,figure,tr{break-inside:avoid}
.box{border:1px solid #999;background:none}figure svg{max-width:100%}}
"""

# Each table gets a "CSV" link that saves its cells (text, comma-separated, quoted where
# needed) as a file; before printing every collapsed block opens.
_CSV = """<script>(function(){var t=document.querySelectorAll("table");
for(var i=0;i<t.length;i++){(function(tb,k){var rows=[];
tb.querySelectorAll("tr").forEach(function(r){var c=[];
r.querySelectorAll("th,td").forEach(function(x){var v=x.textContent.trim();
c.push(/[",\\n]/.test(v)?'"'+v.replace(/"/g,'""')+'"':v)});rows.push(c.join(","))});
var a=document.createElement("a");a.className="csv";a.textContent="CSV";
a.download=(tb.getAttribute("data-name")||("table-"+(k+1)))+".csv";
var u="data:text/csv;charset=utf-8,"+encodeURIComponent(rows.join("\\n")+"\\n");a.href=u;
tb.insertAdjacentElement("beforebegin",a)})(t[i],i)}
window.addEventListener("beforeprint",function(){
document.querySelectorAll("details").forEach(function(d){d.open=true})})})();</script>"""


def _slug(text: str, used: set[str]) -> str:
    base = re.sub(r"[^a-z0-9]+", "-", re.sub(r"<.*?>", "", text).lower()).strip("-")
    slug, k = base or "section", 2
    while slug in used:
        slug, k = f"{base}-{k}", k + 1
    used.add(slug)
    return slug


_H2 = re.compile(r"<h2( id=([\w-]+))?>(.*?)</h2>", flags=re.S)


def _heads(body: str) -> list[re.Match[str]]:
    """``list(_H2.finditer(body))``: a match starts at '<h2' only, found by str.find
    (the regular expression's scan of a report's 0.6 MB took 0.35 ms, issue 36)."""
    out, at = [], 0
    while (p := body.find("<h2", at)) >= 0:
        m = _H2.match(body, p)
        out += [m] if m else []
        at = m.end() if m else p + 1
    return out


def with_toc(body: str) -> str:
    """``body`` with an id on every <h2> that has none and a table of contents (links to
    every <h2>) before the first of them; unchanged when it has fewer than three."""
    heads = _heads(body)
    if len(heads) < 3:
        return body
    used = {m.group(2) for m in heads if m.group(2)}
    out, items, last = [], [], 0
    for m in heads:
        hid = m.group(2) or _slug(m.group(3), used)
        out.append(body[last : m.start()])
        out.append(f"<h2 id={hid}>{m.group(3)}</h2>")
        title = re.sub(r"<small.*?</small>|<.*?>", "", m.group(3)).strip()
        items.append(f"<li><a href='#{hid}'>{title}</a></li>")
        last = m.end()
    out.append(body[last:])
    text = "".join(out)
    first = text.index("<h2 id=")
    toc = f"<nav class=toc><b>Contents</b><ol>{''.join(items)}</ol></nav>"
    return text[:first] + toc + text[first:]


# After loading, record how many figures are drawn and visible (``data-figures="k/n"`` on
# <html>) and flag broken ones on the page; tests read it with a headless browser.
_CHECK = """<script>window.addEventListener("load",function(){
var f=document.querySelectorAll("figure"),ok=0;for(var i=0;i<f.length;i++){
var s=f[i].querySelector("svg"),r=s?s.getBoundingClientRect():null;
if(s&&r.width>0&&r.height>0&&s.querySelector("path,rect,polygon,polyline")){ok++}
else{f[i].insertAdjacentHTML("beforeend","<p class=bad>figure failed to load</p>")}}
document.documentElement.setAttribute("data-figures",ok+"/"+f.length);});</script>"""


def page(title: str, body: str) -> str:
    """A whole HTML page, self-contained (inline CSS and SVG, no external files)."""
    return "".join(page_parts(title, body))


def page_parts(title: str, body: str, after: Sequence[str] = ()) -> list[str]:
    """:func:`page` of ``body + "".join(after)`` in pieces, ``after`` (text without
    a heading, such as the figures) as they are: a report's ~0.6 MB of ASCII figures
    is not copied into one text with the few characters beyond Latin-1 of its tables
    (two bytes a character) nor encoded as such (1.3 ms for 2000 poses, issue 36)."""
    if any("<h2" in a for a in after):  # the table of contents must see it
        body, after = body + "".join(after), ()
    stamp = time.strftime("%Y-%m-%d %H:%M")
    return [
        f"<!DOCTYPE html><html lang=en><head><meta charset=utf-8><title>{e(title)}</title>"
        f"<style>{_CSS}</style></head><body><h1>{e(title)}</h1>"
        f"<p class=muted>kinecal {__version__}, {stamp}</p>{with_toc(body)}",
        *after,
        f"{_CSV}{_CHECK}</body></html>\n",
    ]


def figure(svg: str, caption: str) -> str:
    """An inline SVG figure with its caption (text, escaped here)."""
    return f"<figure>{svg}<figcaption class=muted>{e(caption)}</figcaption></figure>"

"""MkDocs hooks of the documentation site (``mkdocs.yml``: ``hooks``).

- Math: ``$$ ... $$`` (display) and ``$ ... $`` (inline) outside code are rendered to
  MathML at build time (``latex2mathml``), so pages need no script from a CDN and show
  their equations offline (browsers draw MathML natively).
- The benchmarks page gets its tables from ``benchmarks/results/*.json``
  (``benchmarks.summary``), rendered at build time.
- Seed scene pages (``seeds/NAME.md``) get the scene's parameter table (name, SI unit,
  default, meaning) from the scene itself (``Scene.parameters``), so the page and the
  command line (``jaxmech scenes NAME``) cannot disagree.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from latex2mathml.converter import convert

ROOT = Path(__file__).resolve().parents[1]
# benchmarks/ imports from the repository root; MkDocs restores sys.path after loading a
# hook, so what the hook needs is imported now.
sys.path.insert(0, str(ROOT))
try:
    from benchmarks.summary import render as render_benchmarks
    from jaxmech.scenes import get_scene
    from jaxmech.units import for_reading
finally:
    sys.path.remove(str(ROOT))

_FENCE = re.compile(r"(^```.*?^```[ \t]*$)", re.S | re.M)
_DISPLAY = re.compile(r"\$\$(.+?)\$\$", re.S)
_INLINE = re.compile(r"(?<![\\$\w])\$(?!\s)([^$\n]+?)(?<!\s)\$(?![\w$])")
_CODE_SPAN = re.compile(r"(`+)(.+?)\1")

# seed page -> the scenes it documents
_SCENES = {
    "seeds/flap_msd.md": ["flap_msd"],
    "seeds/landing_gear.md": ["landing_gear"],
    "seeds/arc_track_flap.md": ["arc_track_flap", "arc_track_flap_landing"],
    "seeds/sma_flap.md": ["sma_flap"],
}


def _math(text: str, stash: list) -> str:
    def keep(mathml: str) -> str:
        # a plain word in the Markdown, swapped for the MathML in the HTML (on_page_content):
        # the Markdown parser neither splits a paragraph at <math> nor reads '*' inside it
        stash.append(mathml)
        return f"jaxmechmath{len(stash) - 1}x"

    text = _DISPLAY.sub(lambda m: "\n\n" + keep(convert(m.group(1).strip(), display="block")) + "\n\n", text)

    def inline(line: str) -> str:
        parts = _CODE_SPAN.split(line)
        # split keeps (ticks, body) groups: every 3rd item from 0 is outside code spans
        out = []
        for i, part in enumerate(parts):
            k = i % 3
            if k == 0:
                out.append(_INLINE.sub(lambda m: keep(convert(m.group(1))), part))
            elif k == 2:
                out.append(parts[i - 1] + part + parts[i - 1])
        return "".join(out)

    return "\n".join(inline(ln) for ln in text.split("\n"))


_STASH: dict[str, list] = {}
_PLACEHOLDER = re.compile(r"(<p>)?jaxmechmath(\d+)x(</p>)?")


def render_math(markdown: str, stash: list) -> str:
    """Markdown with its math replaced by placeholders (the MathML appended to ``stash``);
    fenced code blocks are left as they are."""
    pieces = _FENCE.split(markdown)
    return "".join(p if i % 2 else _math(p, stash) for i, p in enumerate(pieces))


def on_page_content(html, page, config, files):
    stash = _STASH.pop(page.file.src_uri, [])
    return _PLACEHOLDER.sub(lambda m: stash[int(m.group(2))] if m.group(1) and m.group(3)
                            else (m.group(1) or "") + stash[int(m.group(2))] + (m.group(3) or ""), html)


def _parameter_table(name: str) -> str:
    scene = get_scene(name)
    rows = ["| parameter | unit | default | meaning |", "|---|---|---|---|"]
    for k, v in scene.defaults.items():
        unit, meaning = scene.parameters[k]
        shown = f"{float(v):.6g}"
        deg, dunit = for_reading(float(v), unit)
        if dunit != unit:
            shown += f" ({deg:.6g} {dunit})"
        rows.append(f"| `{k}` | {unit} | {shown} | {meaning.replace('|', '&#124;')} |")
    return (f"\n\n## Scene `{name}`\n\n{scene.summary}.\n\n`jaxmech run {name}` runs it; "
            f"`jaxmech scenes {name}` prints this table.\n\n" + "\n".join(rows) + "\n")


def _live_table() -> str:
    path = ROOT / "benchmarks" / "results" / "live.json"
    if not path.exists():
        return "_not run yet: `python -m benchmarks.live`_"
    doc = json.loads(path.read_text())
    p, q, m = doc["parameter_update"], doc["pose_update"], doc["machine"]
    return "\n".join([
        "| update | median (ms) | p95 (ms) | samples |", "|---|---:|---:|---:|",
        f"| a parameter moved (scene run + redraw + PNG) | {p['median_ms']:.1f} | {p['p95_ms']:.1f} | {p['n']} |",
        f"| the pose moved (redraw + PNG) | {q['median_ms']:.1f} | {q['p95_ms']:.1f} | {q['n']} |",
        "",
        f"First call (the compile) {doc['first_call_s']:.1f} s; an unassemblable design answered in "
        f"{doc['unassemblable_update_ms']:.0f} ms.  {m.get('cpu_count')} cores, load average "
        f"{', '.join(f'{x:.1f}' for x in doc['load_average_after'])} (1, 5, 15 min), {m['date']}.",
    ])


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri == "benchmarks.md":
        markdown = markdown.replace("<!-- benchmarks:live -->", _live_table())
        markdown = markdown.replace("<!-- benchmarks:tables -->", "## Tables" + render_benchmarks().removeprefix("## Benchmarks"))
        return markdown
    _STASH[page.file.src_uri] = stash = []
    markdown = render_math(markdown, stash)
    for name in _SCENES.get(page.file.src_uri, ()):
        markdown += _parameter_table(name)
    return markdown

"""The documentation site builds as the README says (``mkdocs build --strict``), offline, and
shows what it promises: the notebooks with their plots, the equations, the API reference,
each seed scene's parameters, the benchmarks' plots.  The notebooks are committed executed:
their stamps say no cell changed since it ran (``scripts/execute_notebooks.py``)."""

import hashlib
import os
import re
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
DEAD_PROXY = "http://127.0.0.1:9"  # the discard port: any fetch through it fails at once


def test_readme_gives_the_build_command():
    assert 'pip install -e ".[docs]" && .venv/bin/mkdocs build --strict' in (ROOT / "README.md").read_text()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_committed_executed(path):
    """Every code cell ran (an execution count, the stamp of the source that ran), and a
    notebook that draws a figure shows it (a PNG output)."""
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    for i, cell in enumerate(code):
        stamp = cell.metadata.get("jaxmech", {}).get("source_sha256")
        assert stamp == hashlib.sha256(cell.source.encode()).hexdigest(), (
            f"{path.name}: code cell {i} changed since it was executed; run 'python scripts/execute_notebooks.py {path.stem}'"
        )
        assert cell.execution_count == i + 1, f"{path.name}: cells were not run in order from a fresh kernel"
    draws = any(re.search(r"\b(?:plot_\w+|draw_mechanism|Image|plot|semilogy|subplots)\(", c.source) for c in code)
    shows = any("image/png" in o.get("data", {}) for c in code for o in c.outputs)
    assert shows == draws, f"{path.name}: {'a figure drawn but not shown' if draws else 'a plot from nowhere'}"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built by the README's command, in strict mode, with every network fetch
    made to fail (proxies pointing at a closed port)."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "HTTP_PROXY": DEAD_PROXY, "HTTPS_PROXY": DEAD_PROXY, "http_proxy": DEAD_PROXY,
           "https_proxy": DEAD_PROXY, "NO_PROXY": "", "no_proxy": "", "NO_MKDOCS_2_WARNING": "1",
           "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_site_pages(site):
    for page in ("index.html", "getting-started.html", "theory.html", "benchmarks.html",
                 "seeds/flap_msd.html", "seeds/landing_gear.html", "seeds/arc_track_flap.html", "seeds/sma_flap.html",
                 "api/solve.html", "api/scenes.html", "api/live.html"):
        assert (site / page).is_file(), page
    for nb in NOTEBOOKS:
        html = (site / "notebooks" / f"{nb.stem}.html").read_text()
        assert "data:image/png;base64," in html, f"{nb.stem}: rendered without its plots"


# Matplotlib's animation player (``to_jshtml``, in the landing-gear notebook) links its
# buttons' icon font; offline the buttons lose their icons and still work.
PLAYER_ICONS = "https://maxcdn.bootstrapcdn.com/font-awesome/4.4.0/css/font-awesome.min.css"


def test_nothing_is_loaded_from_the_web(site):
    """No script, stylesheet, font or image is fetched from another host when a page is read
    (the site's theme, search, equations and notebooks all work offline)."""
    pattern = re.compile(r"<(?:script|link|img)\b[^>]*\b(?:src|href)=\"((?:https?:)?//[^\"]*)\"", re.I)
    for page in site.rglob("*.html"):
        assert set(pattern.findall(page.read_text())) <= {PLAYER_ICONS}, page.relative_to(site)


def test_theory_equations_are_mathml(site):
    html = (site / "theory.html").read_text()
    assert html.count("<math") >= 20 and "$$" not in html
    assert "<mi>&#x003A6;</mi>" in html or "<mi>Φ</mi>" in html  # Phi, the loop closure


def test_api_reference_from_docstrings(site):
    html = (site / "api" / "solve.html").read_text()
    assert 'id="jaxmech.solver.positions.solve"' in html and "implicit function theorem" in html
    assert 'id="jaxmech.viz.live.update"' in (site / "api" / "live.html").read_text()


def test_seed_pages_list_the_scene_parameters(site):
    """The arc-track flap page carries both scenes' parameter tables, from the scenes:
    alpha0 = 65 deg, cruise M12 = 750 N m, landing 220 -> 650 N m (Arslan, Table 2, Sec. 5.2)."""
    html = (site / "seeds" / "arc_track_flap.html").read_text()
    assert "arc_track_flap_landing" in html and "1.13446 (65 deg)" in html
    rows = re.findall(r"<td><code>M12_i</code></td>\s*<td>N m</td>\s*<td>([^<]+)</td>", html)
    assert rows == ["750", "220"]


def test_benchmark_plots_are_committed_and_shown(site):
    html = (site / "benchmarks.html").read_text()
    for name in ("kinematics", "speed_error", "scaling", "flap_torque"):
        tracked = subprocess.run(["git", "ls-files", "--error-unmatch", f"docs/img/benchmarks/{name}.png"], cwd=ROOT,
                                 capture_output=True).returncode == 0
        assert tracked or not (ROOT / ".git").exists(), f"docs/img/benchmarks/{name}.png is not committed"
        assert f'src="img/benchmarks/{name}.png"' in html and (site / "img" / "benchmarks" / f"{name}.png").is_file()
    assert "a parameter moved" in html  # the live benchmark's table, from results/live.json


# A seed document's file name: a number and a hash (``000_0e5ea70f9886b82a``), or "Seed 003".
SEED_FILE_NAME = re.compile(r"\b\d{3}_[0-9a-f]{8,}\b|\bseed \d{3}\b", re.I)
SEED_PAGES = sorted((ROOT / "docs" / "seeds").glob("*.md"))


@pytest.mark.parametrize("path", SEED_PAGES, ids=[p.stem for p in SEED_PAGES])
def test_seed_page_is_titled_by_its_document(path):
    """A seed page's title (its first heading, which the site's navigation shows) is the
    document's own title with its authors and year, as its Source paragraph gives them; never
    the seed's file name."""
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("# "), f"{path.name}: the page does not start with its title"
    title = lines[0][2:]
    assert not SEED_FILE_NAME.search(title), f"{path.name}: the title names the seed file: {title!r}"
    m = re.fullmatch(r"(.+) \((.+), (\d{4}(?:/\d{2})?)\)", title)
    assert m, f"{path.name}: the title is not 'Document title (Authors, year)': {title!r}"
    text = "\n".join(lines)
    source = text[text.find("Source:"):].split("\n\n")[0] if "Source:" in text else ""
    authors = re.split(r", | and ", m.group(2))
    assert all(a in source for a in authors), f"{path.name}: authors {authors} not in the Source paragraph"
    assert m.group(3)[:4] in source, f"{path.name}: year {m.group(3)} not in the Source paragraph"


def test_no_page_title_names_a_seed_file(site):
    for page in site.rglob("*.html"):
        html = page.read_text(encoding="utf-8")
        for tag in ("title", "h1"):
            for text in re.findall(rf"<{tag}\b[^>]*>(.*?)</{tag}>", html, re.S):
                assert not SEED_FILE_NAME.search(text), f"{page.relative_to(site)}: <{tag}> {text.strip()!r}"


def test_home_figure_reads_the_crank_angle_in_degrees():
    """The home page's figure (``scripts/draw_home_figure.py``) titles its panels in degrees,
    like every other plot; the script writes the titles into the PNG's text."""
    from PIL import Image

    assert "img/flap_msd_poses.png" in (ROOT / "docs" / "index.md").read_text()
    with Image.open(ROOT / "docs" / "img" / "flap_msd_poses.png") as im:
        titles = im.text.get("Description", "").split("; ")
    assert len(titles) == 3 and all(re.fullmatch(r"alpha = [0-9.]+ deg", t) for t in titles), titles
    assert titles[0] == "alpha = 275 deg" and titles[-1] == "alpha = 320 deg"  # the stroke, report §1

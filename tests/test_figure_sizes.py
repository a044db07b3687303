"""Every PNG the command line writes fits a 1920x1080 screen at its saved dpi (at most
1600 x 1000 px) and stays legible (each panel at least ~1.5 in tall at 110 dpi), for a
built-in scene and a linkage file with many output columns; ``--plot``, ``--transmission``
and ``--ma-output`` choose what is plotted, a wrong name is one line with a "did you mean"."""

import jax

jax.config.update("jax_enable_x64", True)

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.viz.drawing import screen_figure  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WATT = str(ROOT / "examples" / "linkages" / "watt_sixbar.toml")


def size(path: Path) -> tuple:
    with Image.open(path) as im:
        return im.size


def sizes(folder: Path) -> dict:
    return {p.name: size(p) for p in sorted(folder.rglob("*.png"))}


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 15, 31])
def test_screen_figure_grows_within_the_box(n):
    fig, axes = screen_figure(n)
    assert len(axes) == n
    w, h = fig.get_size_inches() * 110
    assert w <= 1600 + 1e-6 and h <= 1000 + 1e-6
    rows = axes[0].get_gridspec().nrows
    assert h / rows >= 1.5 * 110 or n > 30  # legible panels until a figure holds more than 30


@pytest.mark.parametrize("args", [["fourbar"], [WATT]], ids=["scene", "linkage file"])
def test_run_and_sweep_pngs_fit_a_screen(tmp_path, args):
    assert main(["run", *args, "--points", "7", "--out", str(tmp_path / "run")]) == 0
    got = sizes(tmp_path / "run")
    assert len(got) >= 5
    for name, (w, h) in got.items():
        assert w <= 1600 and h <= 1000, (name, w, h)
        assert w >= 400 and h >= 250, (name, w, h)
    (tmp_path / "sweep").mkdir()
    grid = ["--grid", "a=0.9:1.1:2"] if args == ["fourbar"] else ["--grid", "m_crank=1:2:2"]
    assert main(["sweep", *args, *grid, "--points", "5", "--out", str(tmp_path / "sweep" / "s.csv")]) == 0
    for name, (w, h) in sizes(tmp_path / "sweep").items():
        assert w <= 1600 and h <= 1000, (name, w, h)


def test_plot_options_choose_the_columns_and_the_transmission(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", WATT, "--points", "5", "--out", str(out), "--plot", "effort_theta_crank,F_B_x", "--plot", "theta_rocker",
                 "--transmission", "A,B,O4", "--transmission", "E,F,O6", "--ma-output", "theta_link6"]) == 0
    w, h = size(out / "watt_sixbar_outputs.png")
    assert h <= 1000 and w <= 1600
    assert main(["run", WATT, "--points", "5", "--out", str(out), "--plot", "F_B_xx"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "did you mean 'F_B_x'?" in err[0] and "Traceback" not in err[0]
    assert main(["run", WATT, "--points", "5", "--out", str(out), "--transmission", "A,B,O44"]) == 2
    assert "did you mean 'O4'?" in capsys.readouterr().err

"""Draw the figure of the home page and the README, ``docs/img/flap_msd_poses.png``: the MSD
double flap at the start, middle and end of its stroke (``jaxmech.viz.plot.plot_poses`` of the
``flap_msd`` scene, as ``jaxmech run flap_msd`` draws it).

    .venv/bin/python scripts/draw_home_figure.py

The panels' titles give the crank angle as every plot does, in degrees
(``jaxmech.units.for_reading``).  They are also written into the PNG's ``Description``
text, where ``tests/test_docs.py`` reads them without drawing anything.
"""

from __future__ import annotations

from pathlib import Path

from jaxmech.viz.plot import plot_poses
from jaxmech.scenes import get_scene, run_scene

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "flap_msd_poses.png"


def main() -> Path:
    result = run_scene(get_scene("flap_msd"), points=101)
    fig = plot_poses(result)
    titles = [ax.get_title() for ax in fig.axes]
    fig.savefig(OUT, dpi=80, metadata={"Title": "flap_msd at the start, middle and end of its stroke",
                                       "Description": "; ".join(titles)})
    print(f"wrote {OUT.relative_to(OUT.parents[2])}: {'; '.join(titles)}")
    return OUT


if __name__ == "__main__":
    main()

"""The projector-to-camera crosstalk matrices of the paper's board colours, as Markdown
(``simbench crosstalk``; ``results/crosstalk.md``): a report on :mod:`simbench.sim.spectral`'s model."""

from __future__ import annotations

from simbench.sim.scene import paint_reflectance
from simbench.sim.spectral import CAMERA_DATASET, PRIMARY_FWHM_NM, PRIMARY_PEAKS_NM, crosstalk_matrix

__all__ = ["crosstalk_report"]


def crosstalk_report(colours: dict[str, tuple[int, int, int]]) -> str:
    """Markdown: the crosstalk matrix of a perfect white and of each named sRGB paint colour
    (reflectance by :func:`simbench.sim.scene.paint_reflectance`)."""
    lines = [
        "# Projector-to-camera crosstalk matrices",
        "",
        "`K[c, p]`: camera channel c (rows R, G, B) recording projector primary p (columns R, G, B) reflected by the",
        "surface, relative to channel p's response to primary p on a perfect white. Primaries: LEDs at "
        + " / ".join(f"{x:g}" for x in PRIMARY_PEAKS_NM)
        + " nm (FWHM "
        + " / ".join(f"{x:g}" for x in PRIMARY_FWHM_NM)
        + f" nm, assumption); camera: `{CAMERA_DATASET}` sensitivities "
        "(stand-in for the Flea3); surface spectra: Mallett & Yuksel 2019 from the paint reflectance. See "
        "`simbench/sim/spectral.py`.",
        "",
    ]
    entries = [("perfect white (reflectance 1)", (1.0, 1.0, 1.0))] + [
        (f"{name} (sRGB {','.join(map(str, c))})", paint_reflectance(c)) for name, c in colours.items()
    ]
    for title, rgb in entries:
        k = crosstalk_matrix(rgb)
        lines += [
            f"## {title}",
            "",
            f"reflectance RGB {tuple(round(x, 3) for x in rgb)}",
            "",
            "| camera \\ projector | R | G | B |",
            "| --- | --- | --- | --- |",
        ]
        for name, row in zip("RGB", k):
            lines.append(f"| {name} | " + " | ".join(f"{v:.4f}" for v in row) + " |")
        lines.append("")
    return "\n".join(lines)

"""Writing results: Markdown tables, CSV tables and matplotlib figures as PNG bytes (and, for
plots of measured values, vector PDF: for a paper, where a PNG's pixels blur) - shared by every
writer of results (the experiments, the calibration report, the ablations), so that none
of them imports another's internals."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import TYPE_CHECKING


from simbench.io import atomic_write_text

if TYPE_CHECKING:
    import matplotlib.figure

__all__ = ["figure_png", "figure_formats", "figure_files", "markdown_table", "write_table", "panel_row"]


def figure_png(fig: matplotlib.figure.Figure, *, dpi: int) -> bytes:
    """A matplotlib figure as PNG bytes (written atomically by the caller); closes it."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


# no creation date in a PDF: the same figure gives the same bytes (determinism, provenance hashes)
_PDF_METADATA = {"CreationDate": None}
# fonts embedded as TrueType (42), not matplotlib's default Type 3, which journals' PDF checks
# (IEEE PDF eXpress among them) flag
_PDF_RC = {"pdf.fonttype": 42}


def figure_formats(fig: matplotlib.figure.Figure, *, dpi: int) -> dict[str, bytes]:
    """A matplotlib figure as ``{"png": ..., "pdf": ...}``: PNG at ``dpi`` to view, PDF (vector:
    lines, markers and text scale for a paper's column; images inside stay raster; fonts embedded
    as TrueType) to print.  Both deterministic (the PDF carries no creation date); closes the
    figure."""
    import matplotlib
    import matplotlib.pyplot as plt

    out = {}
    for fmt, kw in (("png", {"dpi": dpi}), ("pdf", {"metadata": _PDF_METADATA})):
        buf = io.BytesIO()
        with matplotlib.rc_context(_PDF_RC):
            fig.savefig(buf, format=fmt, **kw)
        out[fmt] = buf.getvalue()
    plt.close(fig)
    return out


def figure_files(stem: str, formats: dict[str, bytes]) -> dict[str, bytes]:
    """``{"STEM.png": ..., "STEM.pdf": ...}`` from :func:`figure_formats`'s result."""
    return {f"{stem}.{fmt}": data for fmt, data in formats.items()}


def markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    """The lines of a Markdown table: ``header`` and one line per row of cells."""
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def table_text(rows: list[dict], columns: list[str]) -> str:
    """``rows`` as CSV text of ``columns`` (floats to 6 significant digits)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def write_table(path_csv: Path, rows: list[dict], columns: list[str]) -> Path:
    """``rows`` as a CSV file of ``columns`` (:func:`table_text`), written atomically."""
    return atomic_write_text(path_csv, table_text(rows, columns))


def panel_row(n_panels: int, width: float = 4.6, *, rows: int = 1) -> tuple:
    """(pyplot, figure, axes): one row of ``n_panels`` panels ``width`` inches wide, on the Agg
    backend (no display needed); ``rows`` > 1: that many such rows, axes of shape (rows, n_panels)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        rows, n_panels, figsize=(width * n_panels, width * 0.82 * rows), constrained_layout=True, squeeze=False
    )
    return plt, fig, axes[0] if rows == 1 else axes

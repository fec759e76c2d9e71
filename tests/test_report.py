"""simbench.report: the writers every table, figure and report of results/ goes through."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simbench.report import figure_files, figure_formats, figure_png, markdown_table, panel_row, write_table


def test_markdown_table_lines():
    assert markdown_table(["a", "b"], [["1", "2"], ["3", "4"]]) == [
        "| a | b |",
        "| --- | --- |",
        "| 1 | 2 |",
        "| 3 | 4 |",
    ]


def test_write_table_writes_six_significant_digits_and_only_its_columns(tmp_path):
    path = write_table(tmp_path / "t.csv", [{"x": 1 / 3, "n": 7, "skip": "me"}], ["x", "n"])
    assert path.read_text() == "x,n\n0.333333,7\n"
    assert not list(tmp_path.glob("*.tmp*"))  # written atomically, nothing left beside it


def test_figure_png_is_a_png_of_the_figure_and_closes_it():
    import matplotlib.pyplot as plt

    plt_, fig, axes = panel_row(2, width=2.0)
    assert len(axes) == 2 and plt_ is plt
    axes[0].imshow(np.eye(4))
    data = figure_png(fig, dpi=50)
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)


def _plot_figure():
    _, fig, axes = panel_row(1, width=2.0)
    axes[0].plot([1.0, 2.0, 3.0], [0.2, 0.1, 0.3], "o-", label="RMSE (mm), sigma")
    axes[0].legend()
    return fig


def test_a_figure_is_written_as_png_and_as_a_vector_pdf_the_same_bytes_every_time():
    """Plots of measured values go in a paper: a vector PDF beside the PNG, whose bytes - like
    the PNG's - do not change between runs (no creation date: provenance hashes and determinism)."""
    import subprocess
    import sys

    import matplotlib.pyplot as plt

    fig = _plot_figure()
    made = figure_formats(fig, dpi=50)
    assert set(made) == {"png", "pdf"} and not plt.fignum_exists(fig.number)
    assert made["png"].startswith(b"\x89PNG\r\n\x1a\n") and made["pdf"].startswith(b"%PDF-")
    assert b"CreationDate" not in made["pdf"]
    assert b"/Type /Font" in made["pdf"]  # text as text (a vector figure), not pixels
    # embedded as TrueType: journals' PDF checks refuse matplotlib's default Type 3 fonts
    assert b"/Type3" not in made["pdf"] and b"CIDFontType2" in made["pdf"]
    assert figure_formats(_plot_figure(), dpi=50) == made
    # and in another process (a date or a process id would differ there)
    code = (
        "import sys; from tests.test_report import _plot_figure; from simbench.report import figure_formats; "
        "sys.stdout.buffer.write(figure_formats(_plot_figure(), dpi=50)['pdf'])"
    )
    root = Path(__file__).resolve().parents[1]
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, cwd=root)
    assert other.returncode == 0, other.stderr.decode()
    assert other.stdout == made["pdf"]
    assert figure_files("fig9", made) == {"fig9.png": made["png"], "fig9.pdf": made["pdf"]}


def test_crosstalk_report_of_a_perfect_white():
    """The report's white matrix has ones on its diagonal by the normalisation it states."""
    from simbench.experiments.crosstalk import crosstalk_report

    text = crosstalk_report({"red": (255, 0, 0)})
    white = text.split("## perfect white")[1].split("## ")[0]
    rows = [line for line in white.splitlines() if line.startswith("| R |") or line.startswith("| G |")]
    assert rows[0].split("|")[2].strip() == "1.0000" and rows[1].split("|")[3].strip() == "1.0000"
    assert "## red (sRGB 255,0,0)" in text

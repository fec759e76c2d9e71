"""simbench.report: the writers every table, figure and report of results/ goes through."""

from __future__ import annotations

import numpy as np

from simbench.report import figure_png, markdown_table, panel_row, write_table


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


def test_crosstalk_report_of_a_perfect_white():
    """The report's white matrix has ones on its diagonal by the normalisation it states."""
    from simbench.experiments.crosstalk import crosstalk_report

    text = crosstalk_report({"red": (255, 0, 0)})
    white = text.split("## perfect white")[1].split("## ")[0]
    rows = [line for line in white.splitlines() if line.startswith("| R |") or line.startswith("| G |")]
    assert rows[0].split("|")[2].strip() == "1.0000" and rows[1].split("|")[3].strip() == "1.0000"
    assert "## red (sRGB 255,0,0)" in text

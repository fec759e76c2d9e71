"""MkDocs hooks of the documentation site (mkdocs.yml): the command-line reference, generated from
the real parser, so it cannot drift from what ``simbench --help`` prints."""

from __future__ import annotations

import argparse
import os

MARKER = "<!-- simbench-cli-reference -->"


def _help(parser: argparse.ArgumentParser) -> str:
    os.environ["COLUMNS"] = "100"  # argparse wraps at the terminal's width: one width for every build
    return parser.format_help().rstrip()


def cli_reference() -> str:
    """Markdown: ``simbench --help`` and each subcommand's help, in the parser's order."""
    from simbench.cli import _parser

    parser = _parser()
    out = ["```text", _help(parser), "```", ""]
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001 - argparse's API
    for action in subs:
        for name, sub in action.choices.items():
            out += [f"## simbench {name}", "", "```text", _help(sub), "```", ""]
            for nested in (a for a in sub._actions if isinstance(a, argparse._SubParsersAction)):  # noqa: SLF001
                for sub_name, leaf in nested.choices.items():
                    out += [f"### simbench {name} {sub_name}", "", "```text", _help(leaf), "```", ""]
    return "\n".join(out)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 - MkDocs' hook signature
    if MARKER in markdown:
        return markdown.replace(MARKER, cli_reference())
    return markdown

"""The README and the documentation pages work as written: every command and code block, run as
a user runs them.

Each fenced block of README.md and of the pages of docs/ (in the site's navigation order) is
executed in a fresh process, from a clean environment (only the virtual environment's ``bin`` on
``PATH``, an empty ``HOME``, no ``PYTHONPATH``), in an empty working folder that holds the
repository's ``scenes/`` and ``simbench/studies/`` as the pages' relative paths expect.
``simbench`` lines run as they are, in order (later lines read what earlier ones wrote); Python
blocks run as scripts; ``make`` lines are checked with ``make -n`` (running them would start
this suite again, or take minutes: CI runs them), and ``simbench ablate`` lines (a built-in study
is tens of full-resolution renders at the run's 36 spp: most of an hour) are parsed by the real
parser and their sweeps loaded, validated and expanded, not run (``tests/test_ablate.py`` runs
sweeps end to end); ``text`` blocks are listings, not run.  Inline ``simbench ...`` commands in
README.md, the docs pages and results/README.md are parsed by the real command-line parser
(alternatives written ``a|b`` are each parsed).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BIN = Path(sys.executable).parent


def doc_pages() -> list[Path]:
    """README.md, then the documentation site's pages in its navigation order (mkdocs.yml)."""
    import yaml

    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    return [README] + [ROOT / "docs" / next(iter(entry.values())) for entry in nav]


def _all_text() -> str:
    return "\n".join(p.read_text() for p in doc_pages())


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced code block."""
    return [(m.group(1).strip(), m.group(2)) for m in re.finditer(r"^```([^\n]*)\n(.*?)^```", text, flags=re.S | re.M)]


def shell_commands(body: str) -> list[str]:
    """The commands of a shell block: continuation lines joined, comments dropped."""
    out, cur = [], ""
    for line in body.splitlines():
        line = line.rstrip()
        if line.endswith("\\"):
            cur += line[:-1] + " "
            continue
        cur += line
        cmd = cur.split("  #", 1)[0].split(" # ", 1)[0].strip()
        cur = ""
        if cmd and not cmd.startswith("#"):
            out.append(cmd)
    return out


def _clean_env(home: Path) -> dict:
    return {
        "PATH": f"{BIN}:/usr/bin:/bin",
        "HOME": str(home),
        "LANG": "C.UTF-8",
        "TMPDIR": os.environ.get("TMPDIR", "/tmp"),
    }


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("readme")
    (d / "home").mkdir()
    (d / "scenes").symlink_to(ROOT / "scenes")
    (d / "simbench").mkdir()
    (d / "simbench" / "studies").symlink_to(ROOT / "simbench" / "studies")
    yield d
    # the README's commands write ~0.7 GB here (their render cache and outputs): freed when the
    # module ends, not with the session, so CI's disk holds one such module's files at a time
    shutil.rmtree(d, ignore_errors=True)


def _run(argv: list[str], cwd: Path, home: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=cwd, env=_clean_env(home), capture_output=True, text=True, timeout=timeout)


def test_the_docs_pages_exist_and_the_readme_stays_short():
    pages = doc_pages()
    missing = [str(p) for p in pages if not p.is_file()]
    assert not missing, missing
    assert len(README.read_text().splitlines()) <= 200  # the details live in docs/


def _without_environment(cmd: str) -> str:
    """A command without its leading ``NAME=value`` words; each must be a variable simbench reads,
    with a value it accepts (the cluster recipe's ``SIMBENCH_THREADS=1 dask worker ...``)."""

    from simbench.threads import THREADS_VARIABLE, process_threads

    words = cmd.split()
    while words and re.match(r"[A-Z_][A-Z0-9_]*=", words[0]):
        name, value = words.pop(0).split("=", 1)
        assert name in (THREADS_VARIABLE, "SIMBENCH_CACHE_DIR"), f"{cmd}: {name} is no variable simbench reads"
        saved = os.environ.get(name)
        os.environ[name] = value
        try:
            process_threads()  # raises for a value simbench refuses
        finally:
            if saved is None:
                del os.environ[name]
            else:
                os.environ[name] = saved
    return " ".join(words)


def test_readme_has_the_blocks_this_test_expects():
    blocks = fenced_blocks(_all_text())
    langs = [lang for lang, _ in blocks]
    assert "python" in langs
    cmds = [
        _without_environment(c)
        for lang, body in blocks
        if lang in ("", "sh", "bash", "console")
        for c in shell_commands(body)
    ]
    assert any(c.startswith("make reproduce") for c in cmds) and any(c.startswith("make test") for c in cmds)
    # beside make and simbench, only the cluster recipe's (docs/usage.md): installing the project
    # on a worker host and starting Dask's scheduler and workers, which need a cluster to run -
    # their Dask subcommands and options are checked against the installed Dask instead
    assert all(c.split()[0] in ("make", "simbench", "pip", "dask") for c in cmds), [
        c for c in cmds if c.split()[0] not in ("make", "simbench", "pip", "dask")
    ]
    for c in (c for c in cmds if c.split()[0] == "dask"):
        words = c.split()
        res = subprocess.run([str(BIN / "dask"), words[1], "--help"], capture_output=True, text=True, timeout=120)
        assert res.returncode == 0, c
        options = {w.split("=")[0] for w in words[2:] if w.startswith("--")}
        assert all(o in res.stdout for o in options), (c, options)


def test_make_targets_in_the_readme_exist():
    blocks = fenced_blocks(_all_text())
    targets = {c.split()[1] for lang, body in blocks for c in shell_commands(body) if c.startswith("make ")}
    targets |= set(re.findall(r"`make ([a-z-]+)`", _all_text()))
    for t in sorted(targets):
        res = subprocess.run(["make", "-n", t], cwd=ROOT, capture_output=True, text=True)
        assert res.returncode == 0, f"make -n {t}: {res.stderr}"


def _inline_commands(text: str) -> list[str]:
    out = []
    for span in re.findall(r"`(simbench [^`]+)`", text):
        if "..." in span or "<" in span or re.search(r"\b[A-Z]{3,}\b", span):
            continue  # a placeholder (FILE, CMD, NAME=VALUE), not a command
        variants = [span]
        for m in re.finditer(r"(\S+)\|(\S+)", span):  # --device kinect|tof -> one command each
            alts = m.group(0).split("|")
            variants = [v.replace(m.group(0), a, 1) for v in variants for a in alts]
        out += variants
    return out


def test_inline_commands_parse():
    from simbench.cli import _parser

    parser = _parser()
    cmds = _inline_commands(_all_text()) + _inline_commands((ROOT / "results" / "README.md").read_text())
    assert len(cmds) > 5
    for cmd in cmds:
        argv = shlex.split(cmd)[1:]
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"README command does not parse: {cmd!r} (exit {exc.code})")


def _check_ablate(argv: list[str], workdir: Path) -> None:
    from simbench.cli import _parser
    from simbench.experiments.ablate import expand, load_sweep

    args = _parser().parse_args(argv[1:])
    for name in args.sweep:
        path = workdir / name if (workdir / name).exists() else name
        assert expand(load_sweep(path)), name


@pytest.mark.slow
def test_every_fenced_block_runs_as_written(workdir):
    """The README's and the docs pages' blocks, in order, in one working folder: each simbench
    line exits 0."""
    blocks = fenced_blocks(_all_text())
    home = workdir / "home"
    ran = 0
    for lang, body in blocks:
        if lang == "python":
            # not in workdir itself: its simbench/ folder (the studies' link) would shadow the package
            (workdir / "blocks").mkdir(exist_ok=True)
            script = workdir / "blocks" / f"block{ran}.py"
            script.write_text(body)
            res = _run([str(BIN / "python"), str(script)], workdir, home)
            assert res.returncode == 0, f"README Python block failed:\n{body}\n{res.stderr[-3000:]}"
            ran += 1
            continue
        if lang not in ("", "sh", "bash", "console"):
            continue  # text: a listing, not commands
        for cmd in shell_commands(body):
            if cmd.startswith("make "):
                continue  # test_make_targets_in_the_readme_exist
            argv = shlex.split(_without_environment(cmd))
            if argv[0] in ("pip", "dask"):
                continue  # the cluster recipe's hosts: test_readme_has_the_blocks_this_test_expects
            if "--scheduler" in argv:  # its cluster's address: parsed here, the path run on a LocalCluster
                from simbench.cli import _parser  # (tests/test_experiments.py)

                _parser().parse_args(argv[1:])
                continue
            if argv[1] == "ablate":
                _check_ablate(argv, workdir)
                continue
            res = _run([str(BIN / argv[0]), *argv[1:]], workdir, home)
            assert res.returncode == 0, f"README command failed: {cmd}\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
            assert "Traceback" not in res.stderr, res.stderr[-3000:]
            ran += 1
    assert ran >= 10

"""The manifest of a recording folder: one format for every depth system's folder.

A recording folder (``simbench render --out``: the proposed sensor's ``meta.json``, a
competitor's or the phase-shift reference's ``device.json``) is decoded with the inputs it was
recorded with - pattern, rig, Z0, device parameters - so those inputs must be the ones written.
The manifest therefore carries

* ``files``: every file of the folder by key, and ``sha256``: the SHA-256 of each, so a file
  replaced, shifted or overwritten later (``decode --out FOLDER/gt_depth.npy``) is seen;
* ``manifest_sha256``: the SHA-256 of the manifest's own content (canonical JSON of every
  other field), so an edit of a decoding input in the manifest itself (``reference_depth_m``,
  the pattern, a device's ``modulation_hz``), or the removal of the ``sha256`` table, is seen.

Both are required: a folder whose manifest lacks them (hand-made, or written by a simbench
older than this format) is refused with the reason, never decoded with guessed inputs.  This
guards against accidents - a hand edit, a copied file, a second tool writing into the folder -
not against someone who recomputes the digests on purpose.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from simbench.io import file_sha256, json_bytes

__all__ = [
    "MANIFEST_FORMAT",
    "ManifestError",
    "seal_manifest",
    "read_manifest",
    "json_object",
    "listed_files",
    "file_sha256",
]

# bumped when the manifest's layout changes (a reader refuses other formats)
MANIFEST_FORMAT = 2
_SELF_KEY = "manifest_sha256"


class ManifestError(ValueError):
    """A recording folder's manifest or files are not what was recorded."""


def _content_sha256(data: dict) -> str:
    body = {k: v for k, v in data.items() if k != _SELF_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def seal_manifest(folder: str | Path, data: dict, files: dict[str, str]) -> dict:
    """``data`` with ``files`` (key -> file name in ``folder``), their SHA-256, the format and
    the manifest's own SHA-256: the dict to write as the folder's manifest.  The files must
    already be written (their bytes are hashed)."""
    folder = Path(folder)
    sealed = {
        **{k: v for k, v in data.items() if k not in ("files", "sha256", _SELF_KEY)},
        "manifest_format": MANIFEST_FORMAT,
        "files": dict(files),
        "sha256": {k: file_sha256(folder / name) for k, name in files.items()},
    }
    # through JSON and back, so that the digest is of what a reader will parse (tuples as lists)
    sealed = json.loads(json_bytes(sealed))
    sealed[_SELF_KEY] = _content_sha256(sealed)
    return sealed


def json_object(path: str | Path) -> dict:
    """The JSON object in the manifest file ``path`` (unchecked), or :class:`ManifestError`."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError):
        raise ManifestError(f"{path}: not valid JSON, so not a recording manifest") from None
    if not isinstance(data, dict):
        raise ManifestError(f"{path}: not a JSON object, so not a recording manifest")
    return data


def read_manifest(path: str | Path, *, verify_files: bool = True) -> dict:
    """The manifest at ``path``, checked: a JSON object of this format whose own SHA-256
    matches, listing its files with their SHA-256; with ``verify_files`` every listed file
    exists and has its recorded SHA-256.

    Raises
    ------
    FileNotFoundError
        No manifest at ``path``.
    ManifestError
        Anything else: says what differs and that the folder cannot be decoded as recorded.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: not a recording folder (`simbench render --out`)")
    data = json_object(path)
    fmt = data.get("manifest_format")
    if fmt != MANIFEST_FORMAT:
        raise ManifestError(
            f"{path}: a manifest of format {fmt!r}, not {MANIFEST_FORMAT}: written by hand or by an older simbench, so "
            "what it was recorded with cannot be trusted; render it again"
        )
    if not isinstance(data.get(_SELF_KEY), str):
        raise ManifestError(
            f"{path}: its seal ({_SELF_KEY}) is missing: written by hand or edited, so what it was recorded with "
            "cannot be trusted; render it again"
        )
    if _content_sha256(data) != data[_SELF_KEY]:
        raise ManifestError(
            f"{path} was edited after it was written (its content's SHA-256 differs from {_SELF_KEY}): the folder "
            "would decode with inputs it was not recorded with; render it again"
        )
    files, digests = data.get("files"), data.get("sha256")
    if not isinstance(files, dict) or not isinstance(digests, dict) or set(files) != set(digests):
        raise ManifestError(f"{path}: its files and sha256 tables do not match")
    for key, name in files.items():
        if not isinstance(name, str) or Path(name).name != name or name in ("", ".", ".."):
            raise ManifestError(f"{path}: file {key!r} is {name!r}, not a file name in the folder")
    if verify_files:
        for key, name in files.items():
            f = path.parent / name
            if not f.is_file():
                raise ManifestError(f"{f} is missing: {path.name} lists it as {key!r}")
            if file_sha256(f) != digests[key]:
                raise ManifestError(
                    f"{f} is not the file recorded in {path.name} (SHA-256 differs): replaced or edited after the "
                    "recording; render it again"
                )
    return data


def listed_files(path: str | Path) -> set[Path]:
    """The resolved paths of the files a manifest lists, and the manifest itself (empty when
    it is missing or unreadable): the files no output may overwrite."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return set()
    files = data.get("files") if isinstance(data, dict) else None
    out = {path.resolve()}
    if isinstance(files, dict):
        out |= {(path.parent / n).resolve() for n in files.values() if isinstance(n, str)}
    return out

"""Phase methods and scene object kinds that other installed packages provide.

A depth system comes from a package through the entry-point group ``simbench.systems``
(:mod:`simbench.systems`); the decoder's phase methods (:data:`simbench.decode.PHASE_METHODS`) and
the scene's object kinds (:data:`simbench.sim.scene.OBJECT_KIND_TABLE`) through the group
:data:`EXTENSION_GROUP`: each entry point names a module that adds its entries to those registries
when it is imported, and simbench imports them, once per process, when a decoder setting or a scene
object first names a phase method or kind it does not know.  So every process - the ``simbench``
command line, a pool's or a Dask cluster's workers - knows them, where an entry added by a script
reaches that script's own process only::

    # my_package's pyproject.toml
    [project.entry-points."simbench.extensions"]
    my_phase = "my_package.my_phase"

What such code makes is cached under its code (:func:`simbench.cache.foreign_code_digest`: the
source of the module defining it), so an edited extension, imported again, does not read what its
earlier version made.  An extension adds names: one that replaces a built-in is put back, with a
warning (:func:`after_load`).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

__all__ = ["EXTENSION_GROUP", "after_load", "load_extensions", "loaded_extensions"]

log = logging.getLogger("simbench")

EXTENSION_GROUP = "simbench.extensions"
_done = False
_loading_in: int | None = None  # the thread importing them now
_lock = threading.Lock()
_LOADED: list[tuple[str, str, str]] = []
_AFTER: list[Callable[[], None]] = []


def after_load(hook: Callable[[], None]) -> None:
    """Have ``hook`` called once the extensions are imported (a registry's owner puts back the
    entries of its own that an extension replaced: an extension adds names, and replacing a
    built-in one would hold in some processes and not others, as the import happens where an
    unknown name is first asked for)."""
    _AFTER.append(hook)


def load_extensions() -> None:
    """Import the modules of :data:`EXTENSION_GROUP`'s entry points, once per process; one that
    fails to import is named in a warning and left out (the others, and simbench, work on).  Other
    threads asking meanwhile wait for them; the importing thread's own nested asks (an extension's
    import reading a registry) return at once."""
    global _done, _loading_in
    if _done or _loading_in == threading.get_ident():
        return
    with _lock:
        if _done:
            return
        _loading_in = threading.get_ident()
        try:
            from importlib.metadata import entry_points

            for ep in entry_points(group=EXTENSION_GROUP):
                package = getattr(ep.dist, "name", None) or "an installed package"
                try:
                    ep.load()
                except Exception as exc:  # noqa: BLE001 - one broken extension does not stop simbench
                    log.warning(
                        "simbench extension %s = %r of %s not loaded: %s: %s",
                        ep.name,
                        ep.value,
                        package,
                        type(exc).__name__,
                        exc,
                    )
                    continue
                _LOADED.append((ep.name, ep.value, package))
            for hook in _AFTER:
                hook()
        finally:
            _loading_in = None
            _done = True


def loaded_extensions() -> list[tuple[str, str, str]]:
    """(name, module, package) of every extension :func:`load_extensions` imported."""
    load_extensions()
    return list(_LOADED)

"""``simbench cache info`` and ``simbench cache prune``: the render cache."""

from __future__ import annotations

import time


from simbench.cli.options import (
    Parser,
    float_in,
    human_bytes,
    size_bytes,
    DEFAULT_CACHE,
)


def _default_not_made(args) -> bool:
    """The default cache folder, before any render made it (a fresh checkout): an empty cache,
    not an error; a folder given with --cache that is not there stays one (a typo)."""
    from pathlib import Path

    return str(args.cache) == str(DEFAULT_CACHE) and not Path(args.cache).exists()


def _cmd_cache_info(args) -> int:
    import shutil

    from simbench.cache import cache_entries, damaged_entries

    if _default_not_made(args):
        print(f"cache {args.cache}: not made yet (0 entries: the first render makes it)")
        return 0
    entries = cache_entries(args.cache)
    damaged = damaged_entries(args.cache)
    kinds: dict[str, list] = {}
    for c in entries:
        kinds.setdefault(c.kind, []).append(c)
    total = sum(c.size_bytes for c in entries)
    free = shutil.disk_usage(args.cache).free
    print(f"cache {args.cache}: {len(entries)} entries, {human_bytes(total)} ({human_bytes(free)} free on its disk)")
    if damaged:  # (an audit: unseen, and never pruned)
        size = sum(p.stat().st_size for p in damaged if p.exists())
        print(
            f"  and {len(damaged)} damaged (files named as entries, not readable as one: {human_bytes(size)}; each is "
            "made again when next needed, `simbench cache prune` removes them)"
        )
    if not entries:
        return 0

    def day(t: float) -> str:
        return time.strftime("%Y-%m-%d %H:%M", time.localtime(t))

    rows = sorted(kinds.items(), key=lambda kv: (-sum(c.size_bytes for c in kv[1]), kv[0]))
    print(f"{'kind':<18} {'entries':>8} {'size':>11}   last used (least .. most recently)")
    for kind, cs in rows:
        used = f"{day(cs[0].last_used_s)} .. {day(cs[-1].last_used_s)}"  # least recently used first
        print(f"{kind:<18} {len(cs):>8} {human_bytes(sum(c.size_bytes for c in cs)):>11}   {used}")
    return 0


def _cmd_cache_prune(args) -> int:
    from simbench.cache import cache_entries, prune_cache

    if args.max_size is None and args.unused_days is None:
        raise ValueError("cache prune: give --max-size, --unused-days or both (what to keep)")
    if _default_not_made(args):
        print(f"cache {args.cache}: not made yet, nothing to remove")
        return 0
    before = cache_entries(args.cache)
    result = prune_cache(
        args.cache,
        max_bytes=args.max_size,
        unused_for_s=None if args.unused_days is None else args.unused_days * 86400.0,
        dry_run=args.dry_run,
    )
    removed = result.entries
    gone = sum(c.size_bytes for c in removed)
    left = sum(c.size_bytes for c in before) - gone
    verb = "would remove" if args.dry_run else "removed"
    if args.dry_run:
        for path in result.paths:
            print(f"would remove {path}")
    extra = f" and {len(result.leftovers)} leftovers (killed writers', damaged entries)" if result.leftovers else ""
    rules = []
    if args.unused_days is not None:
        rules.append(f"those unused for {args.unused_days:g} days")
    if args.max_size is not None:
        rules.append(f"the least recently used beyond {human_bytes(args.max_size)}")
    rule = " and ".join(rules)
    print(
        f"cache {args.cache}: {verb} {len(removed)} entries ({human_bytes(gone)}), {rule}{extra}; "
        f"{len(before) - len(removed)} kept ({human_bytes(left)})"
    )
    return 0


def add_parsers(sub, kw: dict) -> None:
    """Add this module's commands to the command line's subparsers."""
    s = sub.add_parser("cache", help="what the render cache holds, and pruning it", **kw)
    cache_sub = s.add_subparsers(dest="cache_command", required=True, parser_class=Parser)
    c = cache_sub.add_parser("info", help="entries and size per kind, when they were last used, free disk", **kw)
    c.add_argument("--cache", default=DEFAULT_CACHE, help="render cache folder")
    c.set_defaults(fn=_cmd_cache_info)
    c = cache_sub.add_parser(
        "prune",
        help="remove the least recently used entries (a hit marks an entry used; removed ones are made again "
        "when next needed)",
        **kw,
    )
    c.add_argument("--cache", default=DEFAULT_CACHE, help="render cache folder")
    c.add_argument(
        "--max-size",
        type=size_bytes,
        default=None,
        help="keep at most this much, the most recently used (e.g. 10G; K, M, G, T are powers of 1024; a bare "
        "number is bytes: 500 keeps nothing but a tiny entry)",
    )
    c.add_argument(
        "--unused-days",
        type=float_in(lo=0.0),
        default=None,
        help="remove every entry not used for this many days (0: every entry)",
    )
    c.add_argument("--dry-run", action="store_true", help="only say what would be removed")
    c.set_defaults(fn=_cmd_cache_prune)

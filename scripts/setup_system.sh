#!/usr/bin/env bash
# System set-up for simbench: Mitsuba's LLVM variants need libLLVM >= 16 (older ones abort the
# process on the first kernel). Install Debian's libllvm19 when we can (root + apt-get) and none
# is present; otherwise say what to do. Rendering still works without it (scalar_rgb, ~5x slower).
set -u
have_llvm16() {
  for f in /usr/lib/*-linux-gnu/libLLVM*.so* /usr/lib/llvm-*/lib/libLLVM*.so* /usr/lib64/libLLVM*.so* /usr/local/lib/libLLVM*.so*; do
    [ -e "$f" ] || continue
    v=$(basename "$(readlink -f "$f")" | sed -nE 's/^libLLVM[-.]?(so\.)?([0-9]+).*/\2/p')
    [ -z "$v" ] && v=$(echo "$f" | sed -nE 's/.*llvm-([0-9]+).*/\1/p')
    [ -n "$v" ] && [ "$v" -ge 16 ] && return 0
  done
  return 1
}
if have_llvm16; then
  echo "simbench setup: libLLVM >= 16 present"
  exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  echo "simbench setup: installing libllvm19 (Debian) for Mitsuba's llvm_ad_rgb variant"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null && apt-get install -y -qq libllvm19 >/dev/null \
    || echo "simbench setup: could not install libllvm19; rendering will fall back to scalar_rgb"
else
  echo "simbench setup: no libLLVM >= 16 and no root apt-get; install libllvm19 (or LLVM >= 16) yourself," \
       "or rendering falls back to scalar_rgb (about 5x slower)"
fi
exit 0

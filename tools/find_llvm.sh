#!/usr/bin/env bash
# Print the path of a shared libLLVM with major version >= 16 (what Mitsuba's llvm variant needs);
# exit 1 when there is none. Newest first.
set -euo pipefail
for dir in /usr/lib/x86_64-linux-gnu /usr/lib/aarch64-linux-gnu /usr/lib64 /usr/lib /usr/local/lib; do
  [ -d "$dir" ] || continue
  for lib in $(ls "$dir"/libLLVM.so.* "$dir"/libLLVM-*.so* 2>/dev/null | sort -V -r); do
    major=$(basename "$lib" | sed -E 's/^libLLVM[.-](so\.)?([0-9]+).*/\2/')
    if [[ "$major" =~ ^[0-9]+$ ]] && [ "$major" -ge 16 ] && [ "$major" -lt 100 ]; then
      echo "$lib"; exit 0
    fi
  done
done
exit 1

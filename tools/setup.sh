#!/usr/bin/env bash
# One-time set-up for development (called by `make setup`; the Makefile skips it when its stamp is
# newer than requirements.txt). Safe to run again. Works without a terminal (CI=true, no stdin).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
VENV=.venv

die() { echo; echo "make setup: $*" >&2; exit 1; }

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@";
  elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then sudo "$@";
  else return 1; fi
}

apt_install() {
  command -v apt-get >/dev/null || return 1
  as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq || return 1
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@"
}

# 1. A shared LLVM >= 16 for Mitsuba's CPU (llvm_ad_rgb) variant; LLVM 15 makes drjit abort.
if ! tools/find_llvm.sh >/dev/null; then
  echo "No shared libLLVM >= 16 found; installing Debian's libllvm19 ..."
  installed=""
  for pkg in libllvm19 libllvm18 libllvm17 libllvm16; do
    if apt_install "$pkg"; then installed=$pkg; break; fi
  done
  [ -n "$installed" ] && tools/find_llvm.sh >/dev/null || die "Mitsuba needs a shared LLVM >= 16 and none could be installed.
  On Debian/Ubuntu run as root:   apt-get update && apt-get install libllvm19
  (or libllvm16..18), or point DRJIT_LIBLLVM_PATH at an existing libLLVM.so >= 16, then run make again."
fi
echo "LLVM for Mitsuba: $(tools/find_llvm.sh)"

# 2. The virtual environment, Python 3.11 (the version Blender 4.2-5.0 and the bpy wheel use).
if [ ! -x "$VENV/bin/python" ]; then
  command -v "$PY" >/dev/null || apt_install python3.11 python3.11-venv \
    || die "Python 3.11 is required (bpy 5.0 is built for it). Install python3.11 and python3.11-venv."
  "$PY" -m venv "$VENV" 2>/dev/null || { apt_install python3.11-venv && "$PY" -m venv "$VENV"; } \
    || die "'$PY -m venv' failed; install the python3.11-venv package."
fi
"$VENV/bin/python" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
  || die "$VENV is not Python 3.11; delete it and run make again."

# 3. torch: the CPU build only. A plain `pip install torch` on Linux pulls the CUDA build and
#    several GB of nvidia wheels, so install it first from a CPU source.
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)
if ! "$VENV/bin/python" -c 'import importlib.metadata as m, sys; sys.exit(m.version("torch").split("+")[0] != "2.13.0")' 2>/dev/null; then
  "${PIP[@]}" install "torch==2.13.0+cpu" \
    || "${PIP[@]}" install "torch==2.13.0+cpu" --index-url https://download.pytorch.org/whl/cpu \
    || die "Cannot install the CPU build of torch 2.13.0 (from pip's configured sources or download.pytorch.org)."
fi

# 4. The pinned rest, then SceneFit itself as an editable package named `scenefit`.
"${PIP[@]}" install -q -r requirements.txt
# The optional extra for batches on Ray (`scenefit[ray]`), so the tests run the Ray path too.
"${PIP[@]}" install -q -r requirements-ray.txt
"${PIP[@]}" install -q --no-deps -e .
"$VENV/bin/python" -c 'import scenefit.core.data.mesh' || die "the editable install of scenefit does not import."

# 5. For the web target's browser test (tests/blender/test_web_bake_in_browser.py): Debian's chromium
#    (headless, SwiftShader's WebGL) and npm's three with its Draco, meshopt and KTX2 decoders, pinned,
#    in .web/ (ignored by git). Without them that test skips; nothing else needs them.
THREE_VERSION=0.187.0
if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null; then
  apt_install chromium || echo "make setup: could not install chromium; the browser test will skip." >&2
fi
if command -v npm >/dev/null; then
  if [ "$(node -p "require('./.web/node_modules/three/package.json').version" 2>/dev/null)" != "$THREE_VERSION" ]; then
    npm install --no-audit --no-fund --prefix .web "three@$THREE_VERSION" >/dev/null \
      || echo "make setup: npm install three failed; the browser test will skip." >&2
  fi
else
  echo "make setup: no npm; the browser test (and the glTF validator's) will skip." >&2
fi
echo "Set-up done."

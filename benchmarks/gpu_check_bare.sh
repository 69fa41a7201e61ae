#!/bin/bash
# `make gpu-check` on a lent GPU machine whose image has torch, transformers, peft and OpenCV but not
# diffusers, Dr.Jit or Mitsuba, and no network (this workplace's device machines; Python 3.12 there).
#
#   here:   bash benchmarks/gpu_check_bare.sh prepare     # wheels into .whl/ (ignored by git), ~44 MB
#   there:  bash benchmarks/gpu_check_bare.sh run         # with .whl carried; results into $OUT
#
# Mitsuba's wheel is 63 MB; the RGB variants alone (cuda_ad_rgb, llvm_ad_rgb, scalar_rgb) and the plugins
# SceneFit loads fit the 64 MB a run may carry. pyoidn (88 MB) stays behind: adapt does not denoise.
set -euo pipefail
case "${1:-}" in
prepare)
    PY=${PY:-.venv/bin/python}
    mkdir -p .whl && rm -rf .whl/* /tmp/scenefit-mitsuba
    $PY -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp --abi cp312 \
        --platform manylinux_2_28_x86_64 -d .whl mitsuba==3.9.1 drjit==1.5.0
    $PY -m pip download -q --no-deps -d .whl diffusers==0.42.1
    mkdir /tmp/scenefit-mitsuba && (cd /tmp/scenefit-mitsuba && python3 -m zipfile -e "$OLDPWD"/.whl/mitsuba-3.9.1-*.whl . \
        && cd mitsuba && rm -f ./*_mono*.so ./*_spectral*.so data/srgb.coeff && rm -rf data/sunsky \
        && (cd plugins && rm -f ellipsoids*.so sunsky.so timed_sunsky.so bsplinecurve.so linearcurve.so sdfgrid.so volpath*.so))
    (cd /tmp/scenefit-mitsuba && zip -q -9 -r "$OLDPWD"/.whl/mitsuba-rgb.zip mitsuba mitsuba-3.9.1.dist-info)
    rm .whl/mitsuba-3.9.1-*.whl && du -sh .whl ;;
run)
    export PYTHONUNBUFFERED=1 HF_HUB_OFFLINE=1 TRANSFORMERS_OFFLINE=1 TOKENIZERS_PARALLELISM=false
    mkdir -p /tmp/site /tmp/pkg
    for w in .whl/*.whl .whl/*.zip; do python3 -m zipfile -e "$w" /tmp/site; done
    ln -sfn "$PWD" /tmp/pkg/scenefit          # the checkout is the package
    export PYTHONPATH=/tmp/site:/tmp/pkg
    export LD_LIBRARY_PATH=/usr/local/nvidia/lib64:/usr/local/nvidia/lib:${LD_LIBRARY_PATH:-}   # OptiX
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
    timeout 480 python3 benchmarks/gpu_check.py --out "${OUT:-benchmarks/results}" --models /tmp/models ;;
*)
    echo "usage: $0 prepare|run" >&2; exit 2 ;;
esac

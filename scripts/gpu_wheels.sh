#!/usr/bin/env bash
# The cp312 wheels a GPU machine without internet lacks for scripts/gpu_check.sh, into .whl/
# (ignored by git; carry it to the machine). The machine's image has torch (CUDA), numpy,
# scipy, pyarrow, pyyaml, tqdm and pytest; the checks also import Mitsuba, Dr.Jit, pydantic and
# threadpoolctl.
# Mitsuba's 62 MB wheel is slimmed to its rgb variants (the project uses scalar_rgb,
# llvm_ad_rgb and cuda_ad_rgb) so that the tree and the wheels travel in 64 MiB (~55 MB).
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p .whl
rm -f .whl/*.whl
py=(--only-binary=:all: --no-deps --python-version 3.12 --implementation cp
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64
    --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64)
pkgs=(mitsuba==3.9.1 drjit==1.5.0)
here=python3; [ -x .venv/bin/python ] && here=.venv/bin/python
for name in pydantic pydantic_core annotated_types typing_inspection threadpoolctl; do  # as here
    pkgs+=("$name==$($here -c "import importlib.metadata as m; print(m.version('$name'))")")
done
python3 -m pip download -q "${py[@]}" -d .whl "${pkgs[@]}"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
wheel=$(ls .whl/mitsuba-*.whl)
(cd "$tmp" && unzip -q "$OLDPWD/$wheel" \
    && rm -f mitsuba/*_mono*.so mitsuba/*_spectral*.so mitsuba/*polarized*.so \
    && rm -rf mitsuba/include mitsuba/cmake \
    && rm "$OLDPWD/$wheel" && zip -q -r -9 "$OLDPWD/$wheel" .)
du -sh .whl

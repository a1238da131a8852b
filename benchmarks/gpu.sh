#!/usr/bin/env bash
# The GPU check: the tests, run.py and scaling.py on a GPU machine. UNTESTED: no GPU was at hand when it was written; run it whenever one is.
#
#   bash benchmarks/gpu.sh [OUT_DIR]          # default: benchmarks/results/gpu-<date>
#
# In a fresh virtual environment: this checkout with the CUDA build of the same jax version, then
#   OUT/env.txt        nvidia-smi, the jax version and jax.devices()
#   OUT/tests.txt      tests/test_train.py (the training loop on the GPU) and tests/test_distributed.py
#                      (its workers run on forced CPU host devices by design: the sharding logic with
#                      the CUDA jax installed)
#   OUT/scaling.md     benchmarks/scaling.py --platform gpu: 1, 2, 4, ... GPUs in one process, and
#   OUT/scaling.json   1 and 2 processes (one GPU each) when there are two GPUs or more
#   OUT/repro_cost.json  benchmarks/repro_cost.py: seconds per training step and hours to the release budget of
#                      each HumanEva-I config (DATA=/path/to/data_3d_humaneva15.npz; skipped without it)
# Commit OUT/scaling.md under benchmarks/results/ and add its line to benchmarks/results/README.md.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-benchmarks/results/gpu-$(date +%Y-%m-%d)}"
mkdir -p "$out"
venv="${TMPDIR:-/tmp}/jaxmotion-gpu-venv"
rm -rf "$venv"
python3 -m venv "$venv"
# shellcheck disable=SC1091
source "$venv/bin/activate"
python -m pip install -q --upgrade pip
python -m pip install -q -e ".[test]"
jax_version="$(python -c 'import jax; print(jax.__version__)')"
python -m pip install -q "jax[cuda12]==${jax_version}"   # the CUDA 12 plugin of the same version (CUDA libraries from pip)

ngpu="$(nvidia-smi -L | wc -l)"
{
  nvidia-smi
  python -c 'import jax; print("jax", jax.__version__, jax.devices())'
} > "$out/env.txt" 2>&1
if ! python -c 'import jax, sys; sys.exit(jax.devices()[0].platform != "gpu")'; then
  echo "jax sees no GPU (see $out/env.txt)" >&2
  exit 1
fi

# The tests: a failure is written down, and the benchmark still runs.
python -m pytest -q -o addopts=-ra tests/test_train.py tests/test_distributed.py > "$out/tests.txt" 2>&1 \
  && echo "tests passed" || echo "tests FAILED: see $out/tests.txt"

devices=()
for d in 1 2 4 8 16; do
  if [ "$d" -le "$ngpu" ]; then devices+=("$d"); fi
done
processes=(1)
if [ "$ngpu" -ge 2 ]; then processes+=(2); fi
# Every device and process count must divide the global batch (64) and the evaluation batch (64).
python benchmarks/scaling.py --platform gpu --devices "${devices[@]}" --processes "${processes[@]}" --out "$out/scaling" \
  2> "$out/scaling.log"
if [ -n "${DATA:-}" ]; then
  python benchmarks/repro_cost.py --data "$DATA" --out "$out/repro_cost.json" --configs \
    experiments/configs/dlow_humaneva.py,experiments/configs/mojo_vae_dct5_humaneva.py,experiments/configs/mojo_vae_dct20_humaneva.py,experiments/configs/divsamp_humaneva.py,experiments/configs/gsps_humaneva.py \
    > "$out/repro_cost.txt" 2>&1 || echo "repro_cost FAILED: see $out/repro_cost.txt"
fi
echo "wrote $out"

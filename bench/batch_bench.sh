#!/usr/bin/env bash
# The batch benchmark (bench/batch_bench.py) in the e2e Blender root, one step per hold of
# the root's lock so that other e2e runs are not kept waiting for the whole benchmark.
#   bash bench/batch_bench.sh [--files N]     (root needed; default 200 files)
set -euo pipefail
cd "$(dirname "$0")/.."
step() { bash bench/in_root.sh bash -c "cd /work && python3 -m bench.batch_bench $*"; }
step prepare "$@"
for m in ${BATCH_BENCH_MODES:-loop jobs1 jobs2 dask2 jobs1_k jobs2_k dask2_k}; do
    uptime
    step mode "$m"
done
step memory
step table

#!/usr/bin/env bash
# Set up everything (idempotent) and run the demo: the paper's porcelain ring to a USD cache.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_setup.sh
setup_main
mkdir -p out
exec .venv/bin/taichi-frac run single_ring -o out/single_ring.usdc "$@"

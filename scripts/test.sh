#!/usr/bin/env bash
# Set up everything (idempotent, quick when already done) and run the whole test suite.
# Extra arguments go to pytest, e.g. scripts/test.sh -k usd
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_setup.sh
setup_main
setup_blender
exec .venv/bin/python -m pytest "$@"

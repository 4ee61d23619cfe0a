#!/usr/bin/env bash
# Install everything datagen needs on a fresh Debian (bookworm) machine, as root:
#   * Debian's libllvm19, which Mitsuba's LLVM backend (llvm_ad_rgb) loads at run
#     time (with LLVM 14 that backend is disabled; with 15 or 16 the process aborts);
#   * a virtual environment in .venv with datagen and its test extras.
# Idempotent: a second run only checks. Usage: bash scripts/install.sh
set -euo pipefail
cd "$(dirname "$0")/.."

if ! dpkg -s libllvm19 >/dev/null 2>&1; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq libllvm19 >/dev/null
fi

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    if ! "$PYTHON" -m venv .venv 2>/dev/null; then
        # Debian's own python3 ships venv separately.
        rm -rf .venv
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq python3-venv >/dev/null
        "$PYTHON" -m venv .venv
    fi
fi
.venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".[test]"
# The lowest versions pyproject.toml declares, in a venv of their own (.venv/floor):
# tests/test_versions.py builds, audits and reads a dataset there. Remade when they change.
.venv/bin/python scripts/declared_floor.py --constraints > .venv/floor-constraints.txt
if ! cmp -s .venv/floor-constraints.txt .venv/floor/constraints.txt 2>/dev/null; then
    rm -rf .venv/floor
    "$PYTHON" -m venv .venv/floor
    .venv/floor/bin/python -m pip install -q --disable-pip-version-check -c .venv/floor-constraints.txt \
        -e . pandas polars
    cp .venv/floor-constraints.txt .venv/floor/constraints.txt
fi
.venv/bin/python -c "import datagen, mitsuba; print('datagen', datagen.__version__, '| mitsuba', mitsuba.__version__, '| variants', ', '.join(mitsuba.variants()))"

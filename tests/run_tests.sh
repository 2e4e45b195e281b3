#!/usr/bin/env bash
# Install the project with its test extra, set up the pycachesim oracle in a
# folder of its own (.oracle/, never on the project's sys.path: its import name
# is also `cachesim`), then run the test suite. Extra arguments go to pytest.
#
#   bash tests/run_tests.sh            the whole suite, kernels compiled by numba
#   bash tests/run_tests.sh --nojit    the suite with NUMBA_DISABLE_JIT=1, kernels
#                                      run as plain Python so coverage.py sees their
#                                      lines; tests marked jit_only are skipped and
#                                      the run fails below 85% of library lines
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
NOJIT=0
if [ "${1:-}" = "--nojit" ]; then
    NOJIT=1
    shift
fi
"$PY" -m pip install --quiet --disable-pip-version-check -e ".[test]"
if [ ! -d .oracle/pycachesim/cachesim ]; then
    "$PY" -m pip install --quiet --disable-pip-version-check \
        --target .oracle/pycachesim pycachesim==0.3.1 \
        || echo "warning: pycachesim oracle could not be installed; its tests will be skipped" >&2
fi
if [ "$NOJIT" = 1 ]; then
    export NUMBA_DISABLE_JIT=1
    exec "$PY" -m pytest --cov --cov-report=term --cov-fail-under=85 "$@"
fi
exec "$PY" -m pytest "$@"

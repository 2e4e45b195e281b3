#!/usr/bin/env bash
# Install the project with its test extra, set up the pycachesim oracle in a
# folder of its own (.oracle/, never on the project's sys.path: its import name
# is also `cachesim`), then run the test suite. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
"$PY" -m pip install --quiet --disable-pip-version-check -e ".[test]"
if [ ! -d .oracle/pycachesim/cachesim ]; then
    "$PY" -m pip install --quiet --disable-pip-version-check \
        --target .oracle/pycachesim pycachesim==0.3.1 \
        || echo "warning: pycachesim oracle could not be installed; its tests will be skipped" >&2
fi
exec "$PY" -m pytest "$@"

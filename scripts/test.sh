#!/usr/bin/env bash
# Install the test dependencies (Python packages, and Debian's chromium for the browser tests)
# and run the whole test suite. Used by the README and by CI (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x /usr/bin/chromium ] && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  echo "installing chromium (Debian) for the browser tests" >&2
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi
python -m pip install -q -e ".[test]"
# One worker per core (at most four): the suite takes 23 min on one core of a 2-core
# machine, 14 min on two. pytest-benchmark, when some other package brought it in, would
# turn itself off under xdist with a warning, which the suite treats as an error.
python -m pytest -q -n auto --maxprocesses=4 -p no:benchmark "$@"

#!/usr/bin/env bash
# holoslam's two set-up commands, each self-contained on a fresh machine:
#   ./dev.sh demo   install (first time) and run the main job on the bundled household log
#   ./dev.sh test   install (first time) and run the test suite
# Other verbs: ./dev.sh install | bench | lint
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
VENV=.venv

ensure_zbar() {
  # pyzbar needs the zbar shared library (Debian: libzbar0). Install it where we can; holoslam still runs
  # without it (OpenCV decodes QR codes) and says so in one line.
  if ldconfig -p 2>/dev/null | grep -q 'libzbar\.so'; then return 0; fi
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "[holoslam] installing libzbar0 (zbar QR decoder) with apt-get" >&2
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libzbar0 >/dev/null) \
      || echo "[holoslam] notice: could not install libzbar0; QR decoding will use OpenCV only" >&2
  else
    echo "[holoslam] notice: zbar library missing and apt-get not usable here; QR decoding will use OpenCV only" >&2
  fi
}

ensure_venv() {
  local stamp=$VENV/.holoslam-installed
  if [ ! -x $VENV/bin/python ]; then
    "$PY" -m venv $VENV
  fi
  if [ ! -f $stamp ] || [ pyproject.toml -nt $stamp ]; then
    echo "[holoslam] installing holoslam and its dependencies into $VENV" >&2
    $VENV/bin/python -m pip install -q --upgrade pip >/dev/null
    $VENV/bin/python -m pip install -q -e '.[dev]'
    # compile the numba kernels a run uses now, in parallel, instead of during the first run
    $VENV/bin/holoslam warmup || echo "[holoslam] notice: warmup failed; the first run compiles its kernels" >&2
    touch $stamp
  fi
}

cmd=${1:-demo}
shift || true
case "$cmd" in
  install) ensure_zbar; ensure_venv; $VENV/bin/holoslam warmup ;;
  demo)
    ensure_zbar; ensure_venv
    $VENV/bin/holoslam demo -o out/household "$@"
    ;;
  test)
    ensure_zbar; ensure_venv
    $VENV/bin/python -m pytest -q -n 2 "$@"
    ;;
  bench) ensure_zbar; ensure_venv; for b in benchmarks/*.py; do $VENV/bin/python "$b" "$@"; done ;;
  lint) ensure_venv; $VENV/bin/ruff check holoslam tests benchmarks && $VENV/bin/mypy ;;  # mypy: [tool.mypy] in pyproject.toml
  *) echo "usage: ./dev.sh demo|test|install|bench|lint" >&2; exit 2 ;;
esac

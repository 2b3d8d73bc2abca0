#!/usr/bin/env bash
# Install a built triaxcal wheel into a fresh virtual environment with no Rust toolchain on PATH,
# then run the README quick start and `triaxcal demo --no-plot` from outside the source tree.
# Usage: scripts/check_wheel.sh DIST_DIR
set -euo pipefail
dist=${1:?usage: check_wheel.sh DIST_DIR}
root=$(cd "$(dirname "$0")/.." && pwd)
py=${PYTHON:-python3}
wheel=$(ls "$dist"/triaxcal-*.whl | head -n 1)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$py" -m venv "$work/venv"
# PATH with only the venv and the system directories: no cargo, rustc or maturin
export PATH="$work/venv/bin:/usr/local/bin:/usr/bin:/bin"
hash -r
if command -v cargo >/dev/null 2>&1 || command -v rustc >/dev/null 2>&1; then
  echo "check_wheel: a Rust toolchain is still on PATH ($(command -v cargo rustc))" >&2
  exit 1
fi
python -m pip install -q --upgrade pip
python -m pip install -q "$wheel"
echo "installed $(basename "$wheel") into a venv with no Rust toolchain"
# the benchmark hooks (cargo feature bench-hooks) are for the development build only
if python -c "import sys, triaxcal._core as c; sys.exit(not (hasattr(c, 'time_fit') or hasattr(c, 'repeat_call')))"; then
  echo "check_wheel: the wheel's core carries the benchmark hooks (built with bench-hooks)" >&2
  exit 1
fi

case "$(uname -s)" in
  Linux)
    # the extension must not need a newer glibc than its manylinux tag promises
    so=$(python -c "import triaxcal._core as c; print(c.__file__)")
    tag=$(basename "$wheel" | sed -n 's/.*manylinux_\([0-9]*\)_\([0-9]*\)_.*/\1.\2/p')
    need=$(objdump -T "$so" | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -V | tail -n 1)
    echo "glibc: wheel tag allows $tag, the extension needs $need"
    if [ -n "$tag" ] && [ "$(printf '%s\n%s\n' "$need" "$tag" | sort -V | tail -n 1)" != "$tag" ]; then
      echo "check_wheel: the extension needs glibc $need, newer than its tag $tag" >&2
      exit 1
    fi
    ;;
esac

cd "$work"
python "$root/scripts/readme_quickstart.py"
triaxcal demo --no-plot --out-dir "$work/demo" --speed 40
test -s "$work/demo/calibration.json"
echo "check_wheel: quick start and demo ran from the installed wheel"

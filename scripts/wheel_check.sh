#!/usr/bin/env bash
# `make wheel-check`: what a user gets from `pip install endocal-toolkit`, checked as a user runs it.
#
# Builds the sdist and the wheel from it (`python -m build`), installs the wheel into a fresh
# venv (its dependencies from the package index, as pip is configured), then, in an empty
# folder outside the source tree: `endocal --help`, `endocal --version`, and the demo's first
# command (`endocal excite planes --out DIR --seed 1`, scripts/demo.sh), whose protocol must
# come from the wheel's own copy (endocal/_protocols). Exits non-zero on the first failure.
#
#   bash scripts/wheel_check.sh [BUILD_PYTHON]     # a Python with `build` (default .venv/bin/python)
#   PYTHON=python3.12 bash scripts/wheel_check.sh  # the interpreter of the fresh venv (default python3)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD_PY=${1:-$ROOT/.venv/bin/python}
PYTHON=${PYTHON:-python3}
unset PYTHONPATH  # the installed package, never the source tree
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
step() { local t0=$SECONDS; printf '== %s\n' "$1"; "${@:2}"; printf '   (%d s)\n' $((SECONDS - t0)); }
fail() { echo "wheel-check: $*" >&2; exit 1; }
quiet() { "$@" >/dev/null; }

build() {
  "$BUILD_PY" -m build --outdir "$TMP/dist" "$ROOT" >"$TMP/build.log" 2>&1 || { cat "$TMP/build.log"; fail "python -m build failed"; }
}
step "python -m build (sdist, then the wheel from it)" build
WHEEL=$(ls "$TMP"/dist/*.whl)
VERSION=$("$BUILD_PY" -c 'import sys; sys.path.insert(0, sys.argv[1]); from endocal._version import __version__; print(__version__)' "$ROOT")
case "$WHEEL" in */endocal_toolkit-"$VERSION"-py3-none-any.whl) ;; *) fail "wheel $WHEEL is not version $VERSION";; esac
LISTING=$("$BUILD_PY" -m zipfile -l "$WHEEL")
for f in "endocal_toolkit-$VERSION.dist-info/licenses/LICENSE" endocal/_protocols/planes.toml endocal/cli/__init__.py; do
  grep -q " *$f " <<<"$LISTING" || fail "$f is missing from $(basename "$WHEEL")"
done

install() {
  "$PYTHON" -m venv "$TMP/venv"
  # --no-compile: the check runs each module once; compiling every dependency's bytecode doubles the install
  "$TMP/venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-compile "$WHEEL"
  "$TMP/venv/bin/python" -m pip check
}
step "install $(basename "$WHEEL") and its dependencies into a fresh venv" install

mkdir "$TMP/work"
cd "$TMP/work"
E=$TMP/venv/bin/endocal
step "endocal --help (in an empty folder)" quiet "$E" --help
said=$("$E" --version)
[ "$said" = "endocal $VERSION" ] || fail "endocal --version says '$said', not 'endocal $VERSION'"
where=$("$TMP/venv/bin/python" -c 'import endocal; print(endocal.__file__)')
case "$where" in "$TMP/venv/"*) ;; *) fail "endocal imported from $where, not from the installed wheel";; esac
step "endocal excite planes --out planes --seed 1 (the demo's first command)" \
  "$E" excite planes --out planes --seed 1 --quiet
"$TMP/venv/bin/python" - "$TMP/venv" <<'EOF' || fail "the run is not what the demo's first command makes"
import json, sys
from pathlib import Path

run = json.loads(Path("planes/run.json").read_text())
source = Path(run["protocol"]["source"]).resolve()
shipped = (Path(sys.argv[1]) / "lib").resolve()
assert run["status"] == "complete", run["status"]
assert source.name == "planes.toml" and source.parent.name == "_protocols" and shipped in source.parents, source
assert Path("planes/aligned.parquet").is_file()
EOF
step "endocal info planes (the run reads back)" quiet "$E" info planes
echo "wheel-check: $(basename "$WHEEL") installs into a fresh venv and runs outside the source tree ($SECONDS s in all)"

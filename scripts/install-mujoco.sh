#!/usr/bin/env bash
# Installs MuJoCo 3.17.0 for kumi's second physics engine, from its PyPI wheel (which ships
# libmujoco.so.3.17.0), into target/mujoco: a virtual environment and lib/libmujoco.so, the
# folder that .cargo/config.toml points the build at (MUJOCO_DYNAMIC_LINK_DIR) and that binaries
# find through their rpath. Nothing is downloaded at build time. Then build with
# `--features mujoco`. `cargo clean` removes it: run this again after one.
set -euo pipefail
cd "$(dirname "$0")/.."
VERSION=3.17.0  # the MuJoCo that mujoco-rs =7.0.0 binds
VENV=target/mujoco/venv
if ! "$VENV/bin/python" -c "import mujoco, sys; sys.exit(mujoco.__version__ != '$VERSION')" 2>/dev/null; then
    echo "== installing mujoco==$VERSION (PyPI) into $VENV"
    python3 -m venv "$VENV"
    # pip's scratch on this disk, not in /tmp (which may be small), and no cache.
    mkdir -p target/pip-tmp
    TMPDIR="$PWD/target/pip-tmp" PIP_NO_CACHE_DIR=1 "$VENV/bin/pip" install --quiet --disable-pip-version-check "mujoco==$VERSION"
fi
PKG=$("$VENV/bin/python" -c "import mujoco, os; print(os.path.dirname(mujoco.__file__))")
mkdir -p target/mujoco/lib
ln -sf "$PKG/libmujoco.so.$VERSION" target/mujoco/lib/libmujoco.so
ln -sf "$PKG/libmujoco.so.$VERSION" "target/mujoco/lib/libmujoco.so.$VERSION"
echo "== MuJoCo $VERSION: $(readlink -f target/mujoco/lib/libmujoco.so)"
